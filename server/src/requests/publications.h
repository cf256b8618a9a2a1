// Publications: the live sources one session publishes (docs/protocol.md,
// "Live sources"). A connection with a 'publish' role announces a skeleton
// (or labelled markers and a model: live/marker_feed.h), then pushes frames; its sources end when it says so or when it
// goes away, and a recorded one is written to the record directory then.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <variant>

#include "gmr/server/auth.h"
#include "live/live_source.h"
#include "live/marker_feed.h"
#include "requests/session_link.h"

namespace gmr::server {

class Publications {
 public:
  explicit Publications(SessionLink& link) : link_(link) {}

  // `role`: the session's (publishing needs kPublish).
  Reply publish(const pb::Publish& r, Role role);
  Reply publish_frame(const pb::PublishFrame& r);
  // A marker publication's calibration frames are all in (publish_frame
  // gave no reply then): the calibration, to be computed off the control loop
  // and handed back to calibrated(), whose reply answers that frame. The
  // session reads no request meanwhile. Empty otherwise.
  struct DueCalibration {
    std::uint32_t publication = 0;
    MarkerFeed::Calibration calibration;
  };
  std::optional<DueCalibration> take_due_calibration() { return std::exchange(due_, std::nullopt); }
  // Serves the publication as a live source (and records it when asked), or
  // ends it with the calibration's error. Nothing when it ended meanwhile.
  Reply calibrated(std::uint32_t publication, Result<MarkerFrameSolver> solver);
  Reply unpublish(const pb::Unpublish& r);
  // Every source this session publishes ends with `reason`.
  void end_all(const std::string& reason);
  std::size_t count() const { return publications_.size(); }

 private:
  struct Held {
    std::shared_ptr<LiveSource> source;   // null while a marker publication calibrates
    std::uint64_t bytes = 0;              // LiveSource::held_bytes (or the calibration's), in the memory budget
    std::uint64_t rate_mhz = 0;           // its declared rate, in the send budget
    std::shared_ptr<MarkerFeed> markers;  // a marker publication
    std::string name;
    double frame_time = 0;
    // A marker publication to be recorded: the file, its budget step taken,
    // opened once the calibration gives the skeleton.
    std::string recording;
  };
  // A new publication named `name`: the name free, this session under its bound.
  std::optional<Refusal> room_for(const std::string& name) const;
  // Where a recording of `name` goes, or why none can be made (no record
  // directory). The refusal names the option.
  std::variant<std::string, Refusal> recording_file(const std::string& name) const;
  // The record budget's first step for a new recording (a refusal when the
  // server cannot record now).
  std::optional<Refusal> admit_recording(const std::string& name);
  // The recording of `skeleton` frames at `path`, its first step admitted;
  // when the file cannot be written the step is given back.
  Result<std::unique_ptr<Recording>> open_recording(const std::string& path, const Skeleton& skeleton,
                                                    double frame_time, const std::string& name);
  Reply publish_markers(const pb::Publish& r);
  Reply marker_frame(std::uint32_t id, Held& held, const pb::PublishFrame& r);
  // Hands `values` to the publication's source (the rate hold, the replicas).
  Reply push(LiveSource& source, std::span<const double> values, std::optional<std::uint64_t> index = std::nullopt);
  void end(std::uint32_t id, const std::string& reason);

  SessionLink& link_;
  std::map<std::uint32_t, Held> publications_;
  std::uint32_t next_publication_ = 1;
  std::optional<DueCalibration> due_;
  LogLimiter over_rate_log_{1, std::chrono::seconds(10)};
};

}  // namespace gmr::server
