// LiveSource: a motion whose frames arrive in time from a publisher
// (docs/protocol.md, "Live sources"). It is listed beside the library's
// motions; views of it are ordinary views whose edits are replayed on each
// frame (ViewContent::live_steps), and its streams are driven by its frames
// instead of a timer: each published frame is computed once per distinct view
// content and encoded once per stream, as a library tick is.
//
// Replays of edits run off the control loop (set_replay): a frame goes at
// once to the streams of unedited views, and to the others when the replay
// thread has made their motions. One replay batch per source runs at a time;
// frames that come meanwhile wait, at most kReplayQueue of them (past that
// the oldest waiting is skipped, and its streams count it), so a burst of
// frames passes whole, a source with many edited views costs the control
// loop nothing but the hand-off, and its lag stays bounded.
//
// Touched only on the I/O thread.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"
#include "gmr/server/view.h"
#include "live/recordings.h"
#include "transport/net.h"

namespace gmr::server {

class Stream;

// The declared rate, held: a token bucket that fills at `rate_hz` and holds
// kBurstSeconds of frames (at least kMinBurst). A publisher's jitter and a
// network's bunching pass; a source declared at 1 Hz that sends 300,000
// frames a second gets one a second through, the rest dropped.
class RateHold {
 public:
  static constexpr double kBurstSeconds = 1.0;
  static constexpr double kMinBurst = 16.0;
  RateHold(double rate_hz, Clock::time_point now)
      : rate_(rate_hz), capacity_(std::max(kMinBurst, rate_hz * kBurstSeconds)), tokens_(capacity_), last_(now) {}
  // Whether a frame arriving at `now` is within the rate (it takes a token).
  bool take(Clock::time_point now) {
    if (now > last_) {
      tokens_ = std::min(capacity_, tokens_ + rate_ * std::chrono::duration<double>(now - last_).count());
      last_ = now;
    }
    if (tokens_ < 1.0) return false;
    tokens_ -= 1.0;
    return true;
  }

 private:
  double rate_, capacity_, tokens_;
  Clock::time_point last_;
};

class LiveSource : public std::enable_shared_from_this<LiveSource> {
 public:
  // `skeleton`: the publisher's, pre-rotation channels. `serial` tells this
  // publication from an earlier one of the same name (share keys).
  LiveSource(std::string name, std::uint64_t serial, Skeleton skeleton, double frame_time, double metres_per_unit);

  // Bytes a source of `skeleton` holds while it lives (its skeleton and
  // newest frame, in the copies a frame's fan-out keeps), an estimate for
  // the memory budget.
  static std::uint64_t held_bytes(const Skeleton& skeleton);

  const std::string& name() const { return name_; }
  std::uint64_t serial() const { return serial_; }
  double frame_time() const { return frame_time_; }
  double metres_per_unit() const { return metres_per_unit_; }
  // Frames published so far; the newest has index frames() - 1.
  std::uint64_t frames() const { return frames_; }
  // The newest frame as a one-frame pre-rotation motion; before the first,
  // the skeleton with every channel 0.
  const std::shared_ptr<const Motion>& latest() const { return latest_; }
  bool ended() const { return ended_; }
  // The replica this source is published on (relay.h); empty: this one.
  const std::string& origin() const { return origin_; }
  void set_origin(std::string origin) { origin_ = std::move(origin); }

  // Checks one frame (its size, finite values) and sends it to every stream
  // of this source. An error says which value and why; nothing is sent then.
  // `index`: the frame's number when another replica numbered it (frames
  // that never came are a gap, of at most kMaxIndexGap); none: the next.
  // A frame that comes faster than the declared rate allows (RateHold) is
  // dropped: kOverRate, nothing sent, counted in over_rate().
  enum class Pushed { kSent, kOverRate };
  Result<Pushed> push(std::span<const double> values, std::optional<std::uint64_t> index = std::nullopt,
                      Clock::time_point now = Clock::now());
  static constexpr std::uint64_t kMaxIndexGap = 65536;
  std::uint64_t over_rate() const { return over_rate_; }
  // Ends the source: it takes no more frames, and every stream's subscribers
  // are told `reason` once the frames it took before reached them.
  void end(const std::string& reason);

  // Every accepted frame goes to `recording` from now on.
  void record(std::unique_ptr<Recording> recording) { recording_ = std::move(recording); }
  // The recording (null when not recording), to finish once the source ended.
  std::unique_ptr<Recording> take_recording() { return std::move(recording_); }

  // Where edit replays run (`work`) and where their frames come back to
  // (`home`, the control loop). Not set: replays run inline, in push().
  void set_replay(net::any_io_executor work, net::any_io_executor home);
  // Adds the edit lists it replays to `*total` (on the control loop).
  void count_replays(std::shared_ptr<std::uint64_t> total) { replays_total_ = std::move(total); }

  // A stream that shows this source from now on (Stream::set_live): it gets
  // every frame pushed from now on.
  void attach(const std::shared_ptr<Stream>& stream);
  // Hands `stream` the newest frame, as its view shows it (a subscriber
  // joining a running source starts there); nothing before the first frame,
  // once the source ended, or while the stream is paused or has no target.
  void send_newest(Stream& stream) const;
  // The motion a live view content shows at the newest frame: its edits
  // replayed on it.
  Result<std::shared_ptr<const Motion>> view_motion(const ViewContent& content) const;

 private:
  std::string name_;
  std::uint64_t serial_;
  double frame_time_;
  double metres_per_unit_;
  std::shared_ptr<const Motion> latest_;
  std::uint64_t frames_ = 0;
  bool ended_ = false;
  std::vector<std::weak_ptr<Stream>> streams_;
  std::uint64_t replay_failures_ = 0;
  // A frame's edited views, for the replay thread: each distinct edit list
  // once, with the streams that show it.
  // Streams whose views have equal edits (ViewContent::live_key): `content`
  // is the first one's, whose edits are replayed for all.
  struct ReplayGroup {
    std::shared_ptr<const ViewContent> content;
    std::vector<std::weak_ptr<Stream>> streams;
    Result<std::shared_ptr<const Motion>> made = std::shared_ptr<const Motion>();
  };
  struct ReplayBatch {
    std::uint64_t index = 0;
    std::shared_ptr<const Motion> frame;
    std::vector<ReplayGroup> groups;
    // Frames dropped from the queue just before this one: its streams count
    // them as skipped when it is delivered, so sequence numbers stay in
    // step with frame numbers.
    std::uint64_t skipped_before = 0;
  };
  // Whether a stream's view `content` shows the edits `g` replays.
  static bool shows(const ViewContent& content, const ReplayGroup& g);
  void start_replay(ReplayBatch batch);
  void finish_replay(ReplayBatch batch);
  // Hands group `g`'s motion (or its failure) to its streams, after
  // `skipped_before` skipped frames.
  void deliver(const ReplayGroup& g, std::uint64_t index, std::uint64_t skipped_before);
  std::optional<net::any_io_executor> replay_work_, replay_home_;
  bool replaying_ = false;
  // Frames waiting for the batch under way, at most kReplayQueue: past that
  // the oldest waiting is skipped by its streams. When the source ends, the
  // batch under way is delivered and those waiting are skipped.
  static constexpr std::size_t kReplayQueue = 8;
  std::deque<ReplayBatch> replay_next_;
  // An end that waits for the replays under way: their frames were taken
  // before it, so subscribers get them first.
  std::optional<std::string> end_reason_;
  void tell_ended(const std::string& reason);
  // Streams of `batch` count its frame, and those skipped before it, as skipped.
  static void skip(const ReplayBatch& batch);
  RateHold hold_;
  std::uint64_t over_rate_ = 0;
  std::shared_ptr<std::uint64_t> replays_total_;
  std::string origin_;
  std::unique_ptr<Recording> recording_;
};

}  // namespace gmr::server
