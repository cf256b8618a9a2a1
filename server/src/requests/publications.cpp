#include "requests/publications.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <utility>

#include "live/announcement.h"

namespace gmr::server {

namespace {

// A new file in `dir` for a recording of `name`: the name with anything but
// letters, digits, '.', '-' and '_' made '_', the UTC time, .gmrb.
std::filesystem::path recording_path(const std::string& dir, const std::string& name) {
  std::string stem;
  for (const char c : name) {
    const bool plain =
        (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' || c == '-' || c == '_';
    stem += plain ? c : '_';
  }
  if (stem.empty() || stem.front() == '.') stem = "live" + stem;
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm utc{};
  gmtime_r(&now, &utc);
  char when[32];
  std::strftime(when, sizeof when, "%Y%m%dT%H%M%SZ", &utc);
  std::filesystem::path p = std::filesystem::path(dir) / (stem + "-" + when + ".gmrb");
  for (int n = 2; std::filesystem::exists(p); ++n) {
    p = std::filesystem::path(dir) / (stem + "-" + when + "-" + std::to_string(n) + ".gmrb");
  }
  return p;
}

}  // namespace

std::optional<Refusal> Publications::room_for(const std::string& name) const {
  if (link_.services.catalog.find(name)) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                   "a motion named '" + name + "' is already served: publish under another name"};
  }
  const std::size_t most = link_.services.cfg.max_publications_per_connection;
  if (publications_.size() >= most) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "at most " + std::to_string(most) + " live sources per connection"};
  }
  return std::nullopt;
}

std::variant<std::string, Refusal> Publications::recording_file(const std::string& name) const {
  const ServerConfig& cfg = link_.services.cfg;
  if (cfg.record_dir.empty()) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                   "this server records no live sources (start it with --record-dir DIR)"};
  }
  return recording_path(cfg.record_dir, name).string();
}

std::optional<Refusal> Publications::admit_recording(const std::string& name) {
  if (const std::string why = link_.services.recordings.budget().admit(); !why.empty()) {
    spdlog::warn("conn {}: live {} not recorded: {}", link_.connection_id, printable(name, 200), why);
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "this server cannot record now: " + why};
  }
  return std::nullopt;
}

Result<std::unique_ptr<Recording>> Publications::open_recording(const std::string& path, const Skeleton& skeleton,
                                                                double frame_time, const std::string& name) {
  RecordBudget& budget = link_.services.recordings.budget();
  Motion pattern;
  pattern.skeleton = skeleton;
  pattern.convention = Convention::kPreRotation;
  pattern.frame_time = frame_time;
  auto file = GmrbAppender::open(pattern, path);
  if (!file.ok()) {
    budget.release(RecordBudget::kStep, 0);
    return make_error("the recording cannot be written: " + file.error().to_string());
  }
  return std::make_unique<Recording>(std::move(file).value(), link_.services.cfg.max_record_bytes, budget, name);
}

Reply Publications::publish(const pb::Publish& r, Role role) {
  if (role < Role::kPublish) {
    return Refusal{pb::ERROR_CODE_PERMISSION_DENIED,
                   "this connection's role is '" + std::string(role_name(role)) +
                       "': publishing a live source needs a 'publish' token (docs/security.md)"};
  }
  if (r.has_markers()) return publish_markers(r);
  const ServerConfig& cfg = link_.services.cfg;
  auto checked = check_announcement(r, cfg);
  if (auto* refusal = std::get_if<Refusal>(&checked)) return std::move(*refusal);
  if (auto refused = room_for(r.name())) return std::move(*refused);
  std::string recording;
  if (r.record()) {
    auto file = recording_file(r.name());
    if (auto* refusal = std::get_if<Refusal>(&file)) return std::move(*refusal);
    recording = std::get<std::string>(std::move(file));
  }
  // The memory budget: the skeleton and its newest frame, as views count
  // their edited copies.
  Admission& admission = link_.services.admission;
  const std::uint64_t bytes = LiveSource::held_bytes(std::get<Skeleton>(checked));
  const std::uint64_t mine = link_.held_bytes + bytes, all = admission.view_bytes() + bytes;
  if (mine > cfg.max_view_bytes_per_connection || all > cfg.max_view_bytes) {
    const bool own = mine > cfg.max_view_bytes_per_connection;
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "the live source's skeleton takes " + std::to_string(bytes) + " bytes; views and live sources " +
                       (own ? "of this connection" : "of all connections") + " would then hold " +
                       std::to_string(own ? mine : all) + " bytes, above the server's limit of " +
                       std::to_string(own ? cfg.max_view_bytes_per_connection : cfg.max_view_bytes)};
  }
  // The send budget: every frame the source takes is computed for its views.
  const double rate = 1.0 / r.frame_time();
  const auto rate_mhz = static_cast<std::uint64_t>(std::llround(rate * 1000.0));
  if (auto refused = admission.commit_rate(rate, rate_mhz, Admission::Asker::kPublication)) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, *refused};
  }
  // The recording: streamed to a temporary beside its file from the first
  // frame, within the record budget (live/recordings.h).
  std::unique_ptr<Recording> recorder;
  if (!recording.empty()) {
    if (auto refused = admit_recording(r.name())) {
      admission.release_rate(rate_mhz);
      return std::move(*refused);
    }
    auto made = open_recording(recording, std::get<Skeleton>(checked), r.frame_time(), r.name());
    if (!made.ok()) {
      admission.release_rate(rate_mhz);
      return Refusal{pb::ERROR_CODE_INTERNAL, made.error().message};
    }
    recorder = std::move(made).value();
  }
  link_.held_bytes = mine;
  admission.set_view_bytes(all);
  auto source = link_.services.catalog.add_live(r.name(), std::move(std::get<Skeleton>(checked)), r.frame_time(),
                                                r.metres_per_unit());
  if (recorder) source->record(std::move(recorder));
  const std::uint32_t id = next_publication_++;
  publications_[id] = Held{source, bytes, rate_mhz, nullptr, r.name(), r.frame_time(), {}};
  link_.services.replicas.announce(*source);
  spdlog::info("conn {}: publishes live {} ({} joints, {} channels, {:.1f} Hz)", link_.connection_id,
               printable(r.name(), 200), source->latest()->skeleton.size(), source->latest()->stride(),
               1.0 / r.frame_time());
  pb::ServerMessage out;
  out.mutable_published()->set_publication_id(id);
  out.mutable_published()->set_motion(r.name());
  out.mutable_published()->set_recording(recording);
  return out;
}

// A marker publication: checked now, served once calibrated (marker_frame).
// Its calibration frames count in the memory budget until then.
Reply Publications::publish_markers(const pb::Publish& r) {
  const ServerConfig& cfg = link_.services.cfg;
  auto made = MarkerFeed::make(r, cfg);
  if (auto* refusal = std::get_if<Refusal>(&made)) return std::move(*refusal);
  auto feed = std::make_shared<MarkerFeed>(std::move(std::get<MarkerFeed>(made)));
  if (auto refused = room_for(r.name())) return std::move(*refused);
  // Recorded from its first solved frame: the file opens with the skeleton
  // the calibration gives (marker_frame); the budget's step is taken now.
  std::string recording;
  if (r.record()) {
    auto file = recording_file(r.name());
    if (auto* refusal = std::get_if<Refusal>(&file)) return std::move(*refusal);
    recording = std::get<std::string>(std::move(file));
  }
  Admission& admission = link_.services.admission;
  const std::uint64_t bytes = feed->held_bytes();
  const std::uint64_t mine = link_.held_bytes + bytes, all = admission.view_bytes() + bytes;
  if (mine > cfg.max_view_bytes_per_connection || all > cfg.max_view_bytes) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "the marker calibration holds " + std::to_string(bytes) +
                       " bytes of frames: above the server's view byte limits (fewer markers, a shorter "
                       "calibration or a lower rate)"};
  }
  const double rate = 1.0 / r.frame_time();
  const auto rate_mhz = static_cast<std::uint64_t>(std::llround(rate * 1000.0));
  if (auto refused = admission.commit_rate(rate, rate_mhz, Admission::Asker::kPublication)) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, *refused};
  }
  if (!recording.empty()) {
    if (auto refused = admit_recording(r.name())) {
      admission.release_rate(rate_mhz);
      return std::move(*refused);
    }
  }
  link_.held_bytes = mine;
  admission.set_view_bytes(all);
  const std::uint32_t id = next_publication_++;
  publications_[id] = Held{nullptr, bytes, rate_mhz, feed, r.name(), r.frame_time(), recording};
  spdlog::info("conn {}: publishes live markers {} ({} markers, model {}, {:.1f} Hz; served after {} frames)",
               link_.connection_id, printable(r.name(), 200), r.markers().names_size(),
               printable(r.markers().model(), 64), rate, feed->calibration_frames());
  pb::ServerMessage out;
  out.mutable_published()->set_publication_id(id);
  out.mutable_published()->set_motion(r.name());
  out.mutable_published()->set_recording(recording);
  return out;
}

Reply Publications::marker_frame(std::uint32_t id, Held& held, const pb::PublishFrame& r) {
  using Fate = LiveDirectory::FrameFate;
  MarkerFeed& feed = *held.markers;
  const MarkerFrameCounts before = feed.counts() ? *feed.counts() : MarkerFrameCounts{};
  auto taken = feed.take(r);
  if (!taken.ok()) {
    link_.services.catalog.count_live_frame(Fate::kRefused);
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "live markers '" + held.name + "': " + taken.error().message};
  }
  if (const MarkerFrameCounts* after = feed.counts()) {
    link_.services.catalog.count_marker_frame(before, *after);
  }
  switch (*taken) {
    case MarkerFeed::Taken::kCalibrating:
    case MarkerFeed::Taken::kSkipped:
      link_.services.catalog.count_live_frame(Fate::kAccepted);
      return pb::ServerMessage{};
    case MarkerFeed::Taken::kCalibrationDue:
      link_.services.catalog.count_live_frame(Fate::kAccepted);
      due_ = DueCalibration{id, feed.take_calibration()};
      return pb::ServerMessage{};
    case MarkerFeed::Taken::kSolved:
      break;
  }
  return push(*held.source, feed.values(), feed.frames() - 1);
}

Reply Publications::calibrated(std::uint32_t id, Result<MarkerFrameSolver> solver) {
  auto it = publications_.find(id);
  if (it == publications_.end()) return pb::ServerMessage{};
  Held& held = it->second;
  MarkerFeed& feed = *held.markers;
  if (auto made = feed.calibrated(std::move(solver)); !made.ok()) {
    const std::string why = "live markers '" + held.name + "': " + made.error().message;
    end(id, why);
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, why};
  }
  if (link_.services.catalog.find(held.name)) {
    const std::string why = "a motion named '" + held.name + "' appeared while the markers calibrated";
    end(id, why);
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, why};
  }
  // The memory budget now holds the skeleton and its newest frame.
  Admission& admission = link_.services.admission;
  const std::uint64_t bytes = LiveSource::held_bytes(feed.skeleton());
  link_.held_bytes = link_.held_bytes - held.bytes + bytes;
  admission.release_view_bytes(held.bytes);
  admission.set_view_bytes(admission.view_bytes() + bytes);
  held.bytes = bytes;
  held.source = link_.services.catalog.add_live(held.name, feed.skeleton(), held.frame_time, feed.metres_per_unit());
  if (!held.recording.empty()) {
    auto made = open_recording(std::exchange(held.recording, {}), feed.skeleton(), held.frame_time, held.name);
    if (!made.ok()) {
      const std::string why = "live markers '" + held.name + "': " + made.error().message;
      end(id, why);
      return Refusal{pb::ERROR_CODE_INTERNAL, why};
    }
    held.source->record(std::move(made).value());
  }
  link_.services.replicas.announce(*held.source);
  spdlog::info("conn {}: live markers {} calibrated on {} frames: served as {} joints", link_.connection_id,
               printable(held.name, 200), feed.calibration_frames(), feed.skeleton().size());
  return pb::ServerMessage{};
}

Reply Publications::publish_frame(const pb::PublishFrame& r) {
  using Fate = LiveDirectory::FrameFate;
  auto it = publications_.find(r.publication_id());
  if (it == publications_.end()) {
    link_.services.catalog.count_live_frame(Fate::kRefused);
    return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown publication " + std::to_string(r.publication_id())};
  }
  if (it->second.markers) return marker_frame(it->first, it->second, r);
  return push(*it->second.source,
              std::span<const double>(r.values().data(), static_cast<std::size_t>(r.values_size())));
}

Reply Publications::push(LiveSource& source, std::span<const double> values, std::optional<std::uint64_t> index) {
  using Fate = LiveDirectory::FrameFate;
  auto pushed = source.push(values, index);
  if (!pushed.ok()) {
    link_.services.catalog.count_live_frame(Fate::kRefused);
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "live '" + source.name() + "': " + pushed.error().message};
  }
  if (pushed.value() == LiveSource::Pushed::kOverRate) {
    // Dropped, not refused: a publisher a little ahead of its clock is not
    // told off per frame. Counted, and logged at a bounded rate.
    link_.services.catalog.count_live_frame(Fate::kOverRate);
    if (std::uint64_t more = 0; over_rate_log_.allow(more)) {
      spdlog::warn("conn {}: live {} sends faster than its declared {:.3g} Hz: {} frames dropped so far",
                   link_.connection_id, printable(source.name(), 200), 1.0 / source.frame_time(), source.over_rate());
    }
    return pb::ServerMessage{};
  }
  link_.services.catalog.count_live_frame(Fate::kAccepted);
  link_.services.replicas.frame(source, values);
  return pb::ServerMessage{};  // no reply
}

Reply Publications::unpublish(const pb::Unpublish& r) {
  if (!publications_.contains(r.publication_id())) {
    return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown publication " + std::to_string(r.publication_id())};
  }
  end(r.publication_id(), "the live source ended");
  return ack();
}

void Publications::end(std::uint32_t id, const std::string& reason) {
  auto it = publications_.find(id);
  if (it == publications_.end()) return;
  auto source = std::move(it->second.source);
  link_.held_bytes -= it->second.bytes;
  link_.services.admission.release_view_bytes(it->second.bytes);
  link_.services.admission.release_rate(it->second.rate_mhz);
  const std::string name = it->second.name;
  const std::string recording_step = it->second.recording;  // a step taken, no file opened
  publications_.erase(it);
  if (!source) {  // a marker publication that had not calibrated yet
    if (!recording_step.empty()) link_.services.recordings.budget().release(RecordBudget::kStep, 0);
    spdlog::info("conn {}: live markers {} ended before their calibration: {}", link_.connection_id,
                 printable(name, 200), reason);
    return;
  }
  link_.services.catalog.remove_live(source);
  spdlog::info("conn {}: live {} ended after {} frames: {}", link_.connection_id, printable(source->name(), 200),
               source->frames(), reason);
  source->end(reason);
  link_.services.replicas.end(*source, reason);
  // Put in place off the I/O thread (atomic: a file appears whole or not at
  // all); the server waits for it when it stops.
  if (auto recording = source->take_recording()) link_.services.recordings.finish(std::move(recording));
}

void Publications::end_all(const std::string& reason) {
  while (!publications_.empty()) end(publications_.begin()->first, reason);
}

}  // namespace gmr::server
