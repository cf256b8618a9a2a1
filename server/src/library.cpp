#include "gmr/server/library.h"

#include <algorithm>
#include <atomic>
#include <map>
#include <mutex>
#include <new>
#include <system_error>
#include <thread>

#include "gmr/core/file_util.h"
#include "gmr/demo/demo_library.h"
#include "gmr/io/motion_file.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/marker_solve.h"
#include "gmr/ops/convert.h"

namespace gmr::server {
namespace fs = std::filesystem;
namespace {

struct Job {
  fs::path path;
  MotionLimits limits;
  LoadOptions options;
  std::string name;
  std::string source;  // the path relative to the library folder: clients never see the server's own paths
  fs::path model;      // a marker file's skeleton model (see marker_model_for)
  std::string stamp;   // of the files it reads (LibraryEntry::stamp)
  const LibraryEntry* previous = nullptr;  // reload: the entry it had
};

std::string file_stamp(const fs::path& p) {
  std::error_code ec, ec2;
  const auto size = fs::file_size(p, ec);
  const auto time = fs::last_write_time(p, ec2);
  if (ec || ec2) return "?";
  return std::to_string(size) + "@" + std::to_string(time.time_since_epoch().count());
}

// The stamp of what a job reads: its file, an .amc's skeleton candidates
// (every .asf of its folder), a marker file's model, the unit sidecars of a
// file without a unit (a missing one stamps "?", so adding one counts).
std::string stamp_of(const Job& job) {
  std::string s = file_stamp(job.path);
  const std::string ext = lower_extension(job.path);
  if (ext == ".bvh" || ext == ".gmr" || ext == ".gmrb") {
    for (const auto& sidecar : unit_sidecars(job.path)) s += "|" + file_stamp(sidecar);
  }
  if (ext == ".amc") {
    std::error_code ec;
    std::vector<fs::path> asfs;
    for (const auto& e : fs::directory_iterator(job.path.parent_path(), ec)) {
      if (lower_extension(e.path()) == ".asf") asfs.push_back(e.path());
    }
    std::sort(asfs.begin(), asfs.end());
    for (const auto& a : asfs) s += "|" + a.filename().string() + ":" + file_stamp(a);
  }
  if (!job.model.empty()) s += "|" + file_stamp(job.model);
  return s;
}

// A marker file (.c3d, .trc) is served when a skeleton model sits beside it:
// X.model for X.c3d, else markers.model for every marker file of the folder.
// The model file holds a model (docs/markers.md) or just `builtin cmu41`.
fs::path marker_model_for(const fs::path& file) {
  std::error_code ec;
  fs::path own = file;
  own.replace_extension(".model");
  if (fs::is_regular_file(own, ec)) return own;
  const fs::path shared = file.parent_path() / "markers.model";
  if (fs::is_regular_file(shared, ec)) return shared;
  return {};
}

// Markers and their model -> the motion the solver builds (pre-rotation).
Result<Motion> load_markers_as_motion(const Job& job, double& metres_per_unit) {
  auto markers = load_markers(job.path);
  if (!markers.ok()) return markers.error();
  metres_per_unit = millimetres_per_marker_unit(markers->units) / 1000;
  auto model = read_marker_model(job.model);
  if (!model.ok()) return model.error();
  auto solved = solve_markers(*markers, *model);
  if (!solved.ok()) {
    Error e = solved.error();
    e.message = "with model " + job.model.filename().string() + ": " + e.message;
    e.file = job.path.string();
    return e;
  }
  return std::move(solved->motion);
}

Result<LibraryEntry> load_one(const Job& job);

// A file too large for this machine is rejected like any other bad file (a
// worker thread must not end the process with std::bad_alloc).
Result<LibraryEntry> load_one_guarded(const Job& job) {
  try {
    return load_one(job);
  } catch (const std::bad_alloc&) {
    return Error{job.path.string(), 0, 0, "out of memory while loading it"};
  }
}

Result<LibraryEntry> load_one(const Job& job) {
  double metres_per_unit = 0;
  auto loaded = job.model.empty() ? load_motion(job.path, job.options) : load_markers_as_motion(job, metres_per_unit);
  if (!loaded.ok()) return loaded.error();
  if (job.model.empty()) {
    auto unit = motion_metres_per_unit(job.path, job.options);
    if (!unit.ok()) return unit.error();
    metres_per_unit = *unit;
  }
  auto pre = to_pre_rotation(*loaded);
  if (!pre.ok()) return pre.error();
  if (auto s = pre->validate(); !s.ok()) return s.error();
  if (pre->frame_count == 0) return Error{job.path.string(), 0, 0, "the motion has no frames"};
  if (!(pre->frame_time > 0.0)) return Error{job.path.string(), 0, 0, "the motion has no frame time"};
  if (auto s = check_motion_limits(*pre, job.limits); !s.ok()) return Error{job.path.string(), 0, 0, s.error().message};
  LibraryEntry e;
  e.name = job.name;
  e.source = job.source;
  e.motion = std::make_shared<const Motion>(std::move(pre).value());
  e.metres_per_unit = metres_per_unit;
  e.version = job.previous != nullptr ? job.previous->version + 1 : 1;
  e.stamp = job.stamp;
  return e;
}

}  // namespace

Status check_motion_limits(const Motion& m, const MotionLimits& limits) {
  const std::uint64_t joints = m.skeleton.size();
  const std::uint64_t frames = m.frame_count;
  // Each product fits in 64 bits: frames and channels are below 2^40 and 2^16.
  const std::uint64_t joint_frames = frames * joints;
  const std::uint64_t value_bytes = frames * m.stride() * sizeof(double);
  if (joint_frames > limits.max_joint_frames) {
    return make_error(ErrorKind::kResourceExhausted,
                      "too large to serve: " + std::to_string(frames) + " frames x " + std::to_string(joints) +
                          " joints = " + std::to_string(joint_frames) + " joint-frames, above the server's limit of " +
                          std::to_string(limits.max_joint_frames) + " (--max-motion-joint-frames)");
  }
  if (value_bytes > limits.max_value_bytes) {
    return make_error(ErrorKind::kResourceExhausted,
                      "too large to serve: " + std::to_string(frames) + " frames x " + std::to_string(m.stride()) +
                          " channels take " + std::to_string(value_bytes) + " bytes, above the server's limit of " +
                          std::to_string(limits.max_value_bytes) + " (--max-motion-bytes)");
  }
  return Ok{};
}

namespace {

// load_library, and reload_library when `previous` is given.
Result<LibraryLoad> load(const fs::path& dir, unsigned threads, const LoadProgress& progress,
                         const MotionLimits& limits, const LoadOptions& file_options,
                         const std::vector<LibraryEntry>* previous, const std::vector<fs::path>& being_written) {
  std::map<std::string, const LibraryEntry*, std::less<>> before;
  if (previous != nullptr) {
    for (const auto& e : *previous) before.emplace(e.source, &e);
  }
  std::vector<fs::path> writing;
  for (const auto& p : being_written) writing.push_back(p.lexically_normal());
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return Error{dir.string(), 0, 0, "not a readable folder"};

  LibraryLoad out;
  std::vector<Job> jobs;
  std::vector<fs::path> files;
  for (auto it = fs::recursive_directory_iterator(dir, fs::directory_options::skip_permission_denied, ec);
       !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
    if (it->is_regular_file(ec)) files.push_back(it->path());
  }
  if (ec) return Error{dir.string(), 0, 0, "cannot list the folder: " + ec.message()};
  std::sort(files.begin(), files.end());
  for (const auto& f : files) {
    const std::string ext = lower_extension(f);
    // The name as found under dir (lexically: relative() would resolve a
    // symbolic link and name its target). An .amc's skeleton is found by
    // load_motion: the .asf of its folder, or of its subject among several.
    const fs::path relative = f.lexically_relative(dir);
    Job job;
    job.path = f;
    job.limits = limits;
    job.options = file_options;
    job.name = fs::path(relative).replace_extension().generic_string();
    job.source = relative.generic_string();
    if (!(ext == ".bvh" || ext == ".gmr" || ext == ".gmrb" || ext == ".amc") &&
        !((ext == ".c3d" || ext == ".trc") && !(job.model = marker_model_for(f)).empty())) {
      ++out.skipped;
      continue;
    }
    if (previous != nullptr) {
      const auto it = before.find(job.source);
      job.previous = it == before.end() ? nullptr : it->second;
      if (std::find(writing.begin(), writing.end(), f.lexically_normal()) != writing.end()) {
        ++out.kept_back;  // half a file is never served: as it was until it is closed
        if (job.previous != nullptr) out.entries.push_back(*job.previous);
        continue;
      }
      job.stamp = stamp_of(job);
      if (job.previous != nullptr && job.previous->stamp == job.stamp) {
        ++out.reused;
        out.entries.push_back(*job.previous);
        continue;
      }
    } else {
      job.stamp = stamp_of(job);
    }
    jobs.push_back(std::move(job));
  }

  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = std::min<unsigned>(threads, static_cast<unsigned>(std::max<std::size_t>(1, jobs.size())));
  std::vector<std::optional<Result<LibraryEntry>>> results(jobs.size());
  std::atomic<std::size_t> next{0};
  std::size_t done = 0;
  std::mutex mutex;
  auto worker = [&] {
    for (std::size_t i; (i = next.fetch_add(1)) < jobs.size();) {
      results[i] = load_one_guarded(jobs[i]);
      std::lock_guard lock(mutex);
      ++done;
      if (progress) {
        const std::string reason = results[i]->ok() ? std::string() : results[i]->error().to_string();
        progress(done, jobs.size(), jobs[i].path, results[i]->ok() ? nullptr : &reason);
      }
    }
  };
  std::vector<std::thread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();

  for (std::size_t i = 0; i < jobs.size(); ++i) {
    if (results[i]->ok()) {
      out.entries.push_back(std::move(*results[i]).value());
    } else {
      out.rejected.push_back({jobs[i].path, results[i]->error().to_string()});
      if (jobs[i].previous != nullptr) {  // the last version that loaded stays
        ++out.kept_back;
        out.entries.push_back(*jobs[i].previous);
      }
    }
  }
  std::sort(out.entries.begin(), out.entries.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  std::sort(out.rejected.begin(), out.rejected.end(), [](const auto& a, const auto& b) { return a.path < b.path; });
  return out;
}

}  // namespace

Result<LibraryLoad> load_library(const fs::path& dir, unsigned threads, const LoadProgress& progress,
                                 const MotionLimits& limits, const LoadOptions& file_options) {
  return load(dir, threads, progress, limits, file_options, nullptr, {});
}

Result<LibraryLoad> reload_library(const fs::path& dir, const std::vector<LibraryEntry>& previous,
                                   const std::vector<fs::path>& being_written, unsigned threads,
                                   const MotionLimits& limits, const LoadOptions& file_options) {
  return load(dir, threads, {}, limits, file_options, &previous, being_written);
}

std::vector<LibraryEntry> builtin_library() {
  std::vector<LibraryEntry> out;
  for (auto& m : demo_library()) {
    // The demo skeletons are built in centimetres (gmr/demo/demo_library.h).
    LibraryEntry& e = out.emplace_back();
    e.name = m.name;
    e.source = "builtin";
    e.motion = std::make_shared<const Motion>(std::move(m.motion));
    e.metres_per_unit = 0.01;
  }
  return out;
}

}  // namespace gmr::server
