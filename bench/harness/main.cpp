// gmr-bench: the research harness, the performance experiments behind
// docs/performance.md (the paper's Figure 4, FK timings). Not a user command:
// it lives in bench/ with the Google Benchmark programs.
//
//   gmr-bench fk FILE [--json] [--repeat N]
//       ns per frame of each FK path on one motion (medians of N timed runs)
//   gmr-bench figure4 [DIR] --out results.csv [--plot figure4.png] [--sets 10] [--seed 1]
//   gmr-bench figure4 --replot results.csv --plot figure4.png
//       the paper's Figure 4: every BVH under DIR, as BVH and as GMR with
//       k = 1..N roots (ten seeded random root sets per k); CSV and a gnuplot PNG
//
// Times are thread CPU time (CLOCK_THREAD_CPUTIME_ID), so other processes on a
// shared machine inflate them less than wall time would; each sample runs the
// whole motion at least ~2 ms. The reported figure is the median sample; `fk`
// also reports the fastest sample, the better estimate on a virtual machine
// whose host preempts it (preemption only ever adds time).
#include <time.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "gmr/ops/convert.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/core/file_util.h"
#include "gmr/io/motion_file.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/join_tree.h"
#include "gmr/ops/set_roots.h"
#include "gmr/ops/shift_root.h"
#include "gmr/ops/split_tree.h"
#include "gmr/ops/strip_dummies.h"

namespace gmr::bench {

// Stops the program with exit status 1 and `what()` as the one line on stderr.
struct CommandError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

template <class T>
T take(Result<T> r) {
  if (!r.ok()) throw CommandError(r.error().to_string());
  return std::move(r).value();
}
void check(const Status& s) {
  if (!s.ok()) throw CommandError(s.error().to_string());
}

namespace {

bool is_bvh(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".bvh";
}

namespace fs = std::filesystem;
using fast::CompiledMotion;
using fast::FkFrameJob;
using fast::FkRangeJob;
using fast::Layout;

double thread_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// ns per frame over the timed samples.
struct Timing {
  double median = 0;
  double min = 0;
};

// ns per frame of `run` (which computes `frames` frames), over `repeats`
// samples of at least `min_sample` seconds each.
Timing ns_per_frame(const std::function<void()>& run, std::size_t frames, int repeats, double min_sample = 2e-3) {
  if (frames == 0) return {};
  run();  // warm caches and the dispatcher
  int inner = 1;
  for (;;) {
    const double t0 = thread_seconds();
    for (int i = 0; i < inner; ++i) run();
    if (thread_seconds() - t0 >= min_sample || inner >= (1 << 20)) break;
    inner *= 2;
  }
  std::vector<double> samples;
  for (int r = 0; r < repeats; ++r) {
    const double t0 = thread_seconds();
    for (int i = 0; i < inner; ++i) run();
    samples.push_back((thread_seconds() - t0) * 1e9 / (static_cast<double>(inner) * static_cast<double>(frames)));
  }
  std::sort(samples.begin(), samples.end());
  return {samples[samples.size() / 2], samples.front()};
}

// The timed paths over every frame of one motion.
Timing time_reference(const Motion& m, int repeats) {
  std::vector<Eigen::Vector3d> pos(m.skeleton.size());
  std::vector<Eigen::Matrix3d> world(m.skeleton.size());
  return ns_per_frame(
      [&] {
        for (std::size_t f = 0; f < m.frame_count; ++f) compute_frame(m, f, pos, world);
      },
      m.frame_count, repeats);
}

Timing time_scalar_float(const CompiledMotion& cm, int repeats) {
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(cm.joint_count() * 3);
  return ns_per_frame(
      [&] {
        for (std::size_t f = 0; f < cm.frame_count(); ++f) fast::scalar_float_frame(cm, f, pos, ws);
      },
      cm.frame_count(), repeats);
}

Timing time_range(const CompiledMotion& cm, Layout layout, int repeats) {
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(cm.frame_count() * cm.joint_count() * 3);
  FkRangeJob job;
  job.motion = &cm;
  job.end = cm.frame_count();
  job.layout = layout;
  job.out_positions = pos;
  job.workspace = ws;
  if (!job.validate()) throw CommandError("internal: " + job.check().error().to_string());
  return ns_per_frame([&] { job.run(); }, cm.frame_count(), repeats);
}

Timing time_single(const CompiledMotion& cm, int repeats) {
  std::vector<float> ws(fast::fk_workspace_size(cm)), pos(cm.joint_count() * 3);
  FkFrameJob job;
  job.motion = &cm;
  job.out_positions = pos;
  job.workspace = ws;
  return ns_per_frame(
      [&] {
        for (std::size_t f = 0; f < cm.frame_count(); ++f) {
          job.frame = f;
          job.run();
        }
      },
      cm.frame_count(), repeats);
}

CompiledMotion compile(const Motion& m) { return take(CompiledMotion::compile(m)); }

// Both forms of a file: post-rotation (BVH) and pre-rotation (GMR).
struct Forms {
  Motion post;
  Motion pre;
};
Forms load_forms(const fs::path& path) {
  Motion m = take(load_motion(path));
  Forms f;
  if (m.convention == Convention::kPostRotation) {
    f.pre = take(to_pre_rotation(m));
    f.post = std::move(m);
  } else {
    f.post = take(to_post_rotation(m));
    f.pre = std::move(m);
  }
  return f;
}

// The GMR form with its own roots plus random joints up to k roots.
Motion with_random_roots(const Motion& pre, std::size_t k, std::mt19937& rng) {
  std::vector<int> roots = pre.skeleton.roots();
  std::vector<int> rest;
  for (int j = 0; j < static_cast<int>(pre.skeleton.size()); ++j) {
    if (!pre.skeleton.is_root(j)) rest.push_back(j);
  }
  std::shuffle(rest.begin(), rest.end(), rng);
  for (int j : rest) {
    if (roots.size() >= k) break;
    roots.push_back(j);
  }
  return take(set_roots(pre, roots));
}

Motion all_roots(const Motion& pre) {
  std::vector<int> roots(pre.skeleton.size());
  for (std::size_t j = 0; j < roots.size(); ++j) roots[j] = static_cast<int>(j);
  return take(set_roots(pre, roots));
}

// ---- gmr bench fk
struct FkOptions {
  std::string file;
  bool json = false;
  int repeat = 15;
};

void run_fk(const FkOptions& o) {
  if (o.repeat < 1) throw CommandError("--repeat must be at least 1");
  const Forms forms = load_forms(o.file);
  const Motion every = all_roots(forms.pre);
  const CompiledMotion bvh = compile(forms.post);
  const CompiledMotion gmr = compile(forms.pre);
  const CompiledMotion gmr_all = compile(every);
  const std::size_t joints = forms.post.skeleton.size();

  // ns per frame, in a fixed order for the text output.
  std::vector<std::pair<std::string, Timing>> ns = {
      {"bvh_reference_double", time_reference(forms.post, o.repeat)},
      {"bvh_scalar", time_scalar_float(bvh, o.repeat)},
      {"bvh_fast", time_range(bvh, Layout::kJointMajor, o.repeat)},
      {"bvh_fast_frame_major", time_range(bvh, Layout::kFrameMajor, o.repeat)},
      {"gmr_one_root", time_range(gmr, Layout::kJointMajor, o.repeat)},
      {"gmr_one_root_frame_major", time_range(gmr, Layout::kFrameMajor, o.repeat)},
      {"gmr_all_roots", time_range(gmr_all, Layout::kFrameMajor, o.repeat)},
      {"gmr_all_roots_view", Timing{}},  // stored_positions(): a zero-copy view
      {"single_frame", time_single(gmr, o.repeat)},
      {"single_frame_bvh", time_single(bvh, o.repeat)},
  };
  const std::vector<std::pair<std::string, std::size_t>> bytes = {
      {"bvh_values_double", forms.post.stride() * sizeof(double)},
      {"gmr_values_double", forms.pre.stride() * sizeof(double)},
      {"compiled_bvh", bvh.bytes_per_frame()},
      {"compiled_gmr_one_root", gmr.bytes_per_frame()},
      {"compiled_gmr_all_roots", gmr_all.bytes_per_frame()},
      {"frame_program_angles", gmr.frame_program_bytes_per_frame()},  // single_frame's frame-major angle copy
      {"positions_float", joints * 3 * sizeof(float)},
  };
  if (o.json) {
    nlohmann::ordered_json j;
    j["file"] = o.file;
    j["frames"] = forms.post.frame_count;
    j["joints"] = joints;
    j["roots"] = forms.pre.skeleton.roots().size();
    j["simd_target"] = fast::simd_target_name();
    j["lanes"] = fast::simd_lanes();
    j["repeats"] = o.repeat;
    j["timer"] = "thread CPU time; ns_per_frame: median of repeats, ns_per_frame_min: fastest repeat";
    for (const auto& [k, v] : ns) j["ns_per_frame"][k] = std::round(v.median * 100.0) / 100.0;
    for (const auto& [k, v] : ns) j["ns_per_frame_min"][k] = std::round(v.min * 100.0) / 100.0;
    for (const auto& [k, v] : bytes) j["bytes_per_frame"][k] = v;
    std::cout << j.dump(2) << "\n";
    return;
  }
  std::printf("%s: %zu frames, %zu joints, SIMD %s (%zu float lanes), %d repeats\n", o.file.c_str(),
              forms.post.frame_count, joints, fast::simd_target_name(), fast::simd_lanes(), o.repeat);
  std::printf("  %-26s %10s %10s\n", "ns per frame", "median", "min");
  for (const auto& [k, v] : ns) std::printf("  %-26s %10.1f %10.1f\n", k.c_str(), v.median, v.min);
  for (const auto& [k, v] : bytes) std::printf("  %-26s %10zu bytes/frame\n", k.c_str(), v);
}

// ---- gmr bench figure4
struct Figure4Options {
  std::string dir = "../shared/data/bvh";
  std::string out;
  std::string plot;
  int sets = 10;
  unsigned seed = 1;
  int repeat = 5;
  int step = 1;
  std::string replot;  // plot this CSV (a previous --out) instead of measuring
};

bool have_program(const std::string& name) {
  const char* path = std::getenv("PATH");
  std::stringstream ss(path == nullptr ? "" : path);
  std::string dir;
  while (std::getline(ss, dir, ':')) {
    std::error_code ec;
    if (!dir.empty() && fs::exists(fs::path(dir) / name, ec)) return true;
  }
  return false;
}

// Shell-quotes a path for gnuplot's single-quoted strings.
std::string gp_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("''") : std::string(1, c);
  return out + "'";
}

// One measurement of the CSV.
struct Row {
  std::string file;
  std::size_t frames = 0, joints = 0, roots = 0;
  std::string method;
  double ns = 0;
};

std::vector<Row> parse_rows(const std::string& csv, const std::string& label) {
  std::vector<Row> rows;
  std::stringstream in(csv);
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    if (number == 1 || line.empty()) continue;  // header
    std::vector<std::string> f;
    std::stringstream ls(line);
    for (std::string item; std::getline(ls, item, ',');) f.push_back(item);
    try {
      if (f.size() != 7) throw std::invalid_argument("fields");
      rows.push_back(Row{f[0], std::stoul(f[1]), std::stoul(f[2]), std::stoul(f[4]), f[3], std::stod(f[6])});
    } catch (const std::exception&) {
      throw CommandError(label + ":" + std::to_string(number) +
                         ": expected file,frames,joints,method,roots,set,ns_per_frame");
    }
  }
  return rows;
}

// The PNG, like the paper's Figure 4: for the skeleton shared by the most
// files (the paper used one skeleton), ns per frame of GMR with k roots (mean
// over the random sets of a file, median over the files) against the BVH
// paths (median over the same files).
void plot_figure4(const std::string& csv, const std::string& png, const std::string& label) {
  const std::vector<Row> rows = parse_rows(csv, label);
  if (!have_program("gnuplot")) {
    std::fprintf(stderr, "gmr bench figure4: gnuplot not found (apt-get install gnuplot-nox): no plot written\n");
    return;
  }
  std::map<std::size_t, std::set<std::string>> files_by_joints;
  for (const Row& r : rows) files_by_joints[r.joints].insert(r.file);
  std::size_t joints = 0, best = 0;
  for (const auto& [j, files] : files_by_joints) {
    if (files.size() > best) best = files.size(), joints = j;
  }
  if (best == 0) throw CommandError(label + ": no measurements to plot");
  // Per file: the mean over its random sets for each k; then, per k, the
  // median over the files (a short file, timed on few frames, would pull a
  // mean far from the rest: a 1-frame file pays a whole 16-frame block).
  std::map<std::size_t, std::map<std::string, std::pair<double, int>>> gmr;  // k -> file -> (sum, n)
  std::map<std::string, std::map<std::string, std::pair<double, int>>> bvh;  // method -> file -> (sum, n)
  for (const Row& r : rows) {
    if (r.joints != joints) continue;
    auto& acc = r.method == "gmr_fast" ? gmr[r.roots][r.file] : bvh[r.method][r.file];
    acc.first += r.ns;
    acc.second += 1;
  }
  const auto median_over_files = [](const std::map<std::string, std::pair<double, int>>& by_file) {
    std::vector<double> v;
    for (const auto& [file, acc] : by_file) v.push_back(acc.first / acc.second);
    std::sort(v.begin(), v.end());
    const std::size_t h = v.size() / 2;
    return v.size() % 2 ? v[h] : (v[h - 1] + v[h]) / 2;
  };
  std::string data;
  for (const auto& [k, by_file] : gmr)
    data += std::to_string(k) + " " + format_double(median_over_files(by_file)) + "\n";
  const auto line = [&](const std::string& method, const std::string& title) {
    const auto it = bvh.find(method);
    if (it == bvh.end()) return std::string();
    return ", " + format_double(median_over_files(it->second)) + " with lines lw 2 title '" + title + "'";
  };
  const fs::path tmp = fs::path(png).parent_path() / ("." + fs::path(png).filename().string() + ".tmp.png");
  const std::string script =
      "set terminal pngcairo size 960,600 font ',11'\n"
      "set output " +
      gp_quote(tmp.string()) +
      "\n"
      "set title \"Positions of every joint per frame: GMR with k roots vs BVH\\n" +
      std::to_string(best) + " files with a " + std::to_string(joints) +
      "-joint skeleton (median over files), random root sets per k, " + fast::simd_target_name() +
      "\"\n"
      "set xlabel 'number of roots k'\nset ylabel 'ns per frame (log scale)'\n"
      "set logscale y\nset grid\nset key outside bottom center horizontal\n"
      "$gmr << EOD\n" +
      data +
      "EOD\n"
      "plot $gmr using 1:2 with linespoints pt 7 ps 0.7 title 'GMR, fast SIMD (mean of the sets per k)'" +
      line("bvh_fast", "BVH, fast SIMD") + line("bvh_scalar_float", "BVH, scalar float") +
      line("bvh_reference_double", "BVH, reference double") + "\n";
  FILE* gp = ::popen("gnuplot", "w");
  if (gp == nullptr) throw CommandError("cannot run gnuplot");
  std::fwrite(script.data(), 1, script.size(), gp);
  const int status = ::pclose(gp);
  if (status != 0) throw CommandError("gnuplot failed (exit status " + std::to_string(status) + ")");
  std::error_code ec;
  fs::rename(tmp, png, ec);
  if (ec) throw CommandError(png + ": " + ec.message());
}

void run_figure4(const Figure4Options& o) {
  if (!o.replot.empty()) {
    if (o.plot.empty()) throw CommandError("--replot needs --plot");
    plot_figure4(take(read_file(o.replot)), o.plot, o.replot);
    return;
  }
  if (o.out.empty()) throw CommandError("--out is required (or --replot CSV --plot PNG)");
  if (o.sets < 1 || o.repeat < 1 || o.step < 1) throw CommandError("--sets, --repeat and --step must be at least 1");
  std::vector<fs::path> files;
  std::error_code ec;
  if (!fs::is_directory(o.dir, ec)) throw CommandError(o.dir + ": not a directory");
  for (fs::recursive_directory_iterator it(o.dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (is_bvh(it->path()) && it->is_regular_file(ec)) files.push_back(it->path());
  }
  if (ec) throw CommandError(o.dir + ": " + ec.message());
  std::sort(files.begin(), files.end());
  if (files.empty()) throw CommandError(o.dir + ": no .bvh files");

  std::string csv = "file,frames,joints,method,roots,set,ns_per_frame\n";
  int used = 0;
  for (std::size_t fi = 0; fi < files.size(); ++fi) {
    const fs::path& path = files[fi];
    auto loaded = load_motion(path);
    if (!loaded || loaded->frame_count == 0) {
      std::fprintf(stderr, "gmr bench figure4: skipping %s: %s\n", path.c_str(),
                   loaded ? "no frames" : loaded.error().to_string().c_str());
      continue;
    }
    const Motion& post = *loaded;
    const Motion pre = take(to_pre_rotation(post));
    const std::size_t n = post.skeleton.size();
    // Lexically: relative() would resolve symbolic links and name their targets.
    const std::string name = path.lexically_relative(o.dir).string();
    const auto row = [&](const std::string& method, std::size_t roots, int set, double ns) {
      csv += name + "," + std::to_string(post.frame_count) + "," + std::to_string(n) + "," + method + "," +
             std::to_string(roots) + "," + std::to_string(set) + "," + format_double(std::round(ns * 100.0) / 100.0) +
             "\n";
    };
    const CompiledMotion bvh = compile(post);
    const double ref = time_reference(post, o.repeat).median;
    const double scalar = time_scalar_float(bvh, o.repeat).median;
    const double fastv = time_range(bvh, Layout::kFrameMajor, o.repeat).median;
    row("bvh_reference_double", post.skeleton.roots().size(), 0, ref);
    row("bvh_scalar_float", post.skeleton.roots().size(), 0, scalar);
    row("bvh_fast", post.skeleton.roots().size(), 0, fastv);
    ++used;
    const std::size_t first = pre.skeleton.roots().size();
    // k = first, first + step, ..., and always n (every joint a root).
    for (std::size_t k = first; k <= n; k = k == n ? n + 1 : std::min(n, k + static_cast<std::size_t>(o.step))) {
      // Only one set of all roots exists; the first k is the conversion's own.
      const int sets = (k == n || k == first) ? 1 : o.sets;
      for (int s = 0; s < sets; ++s) {
        std::mt19937 rng(o.seed * 1000003u + static_cast<unsigned>(fi) * 7919u + static_cast<unsigned>(k) * 31u +
                         static_cast<unsigned>(s));
        const Motion m = k == first ? Motion(pre) : with_random_roots(pre, k, rng);
        const double ns = time_range(compile(m), Layout::kFrameMajor, o.repeat).median;
        row("gmr_fast", k, s, ns);
      }
    }
    std::fprintf(stderr, "gmr-bench figure4: %s: %zu joints, bvh fast %.1f ns/frame\n", name.c_str(), n, fastv);
  }
  if (used == 0) throw CommandError(o.dir + ": no readable .bvh file with frames");
  check(write_file_atomic(o.out, csv));
  if (!o.plot.empty()) plot_figure4(csv, o.plot, o.out);
}

}  // namespace

void add_commands(CLI::App& bench) {
  {
    auto o = std::make_shared<FkOptions>();
    CLI::App* cmd = bench.add_subcommand("fk", "ns per frame of every FK path on one motion file");
    cmd->add_option("FILE", o->file, "Motion file (.bvh, .gmr, .gmrb, .amc)")->required();
    cmd->add_flag("--json", o->json, "One JSON object on stdout");
    cmd->add_option("--repeat", o->repeat, "Timed samples per path (median and fastest reported)")
        ->capture_default_str();
    cmd->callback([o] { run_fk(*o); });
  }
  {
    auto o = std::make_shared<Figure4Options>();
    CLI::App* cmd = bench.add_subcommand("figure4", "The paper's Figure 4: BVH vs GMR with k roots, CSV and PNG");
    cmd->add_option("DIR", o->dir, "Folder searched recursively for .bvh files")->capture_default_str();
    cmd->add_option("--out", o->out, "CSV of every measurement (atomic write)");
    cmd->add_option("--replot", o->replot, "Only plot a CSV written by an earlier --out");
    cmd->add_option("--plot", o->plot, "PNG plot (needs gnuplot)");
    cmd->add_option("--sets", o->sets, "Random root sets per k")->capture_default_str();
    cmd->add_option("--seed", o->seed, "Seed of the root sets")->capture_default_str();
    cmd->add_option("--repeat", o->repeat, "Timed samples per configuration")->capture_default_str();
    cmd->add_option("--step", o->step, "Step between root counts k")->capture_default_str();
    cmd->callback([o] { run_figure4(*o); });
  }
}

}  // namespace gmr::bench

int main(int argc, char** argv) {
  CLI::App app{"gmr-bench: the performance experiments of docs/performance.md"};
  app.require_subcommand(1);
  gmr::bench::add_commands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gmr-bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
