// Stream: one schedule and one view content, fanned out to its targets. Per
// tick: one forward-kinematics pass, one encoding, the same bytes handed to
// every target. Float32 streams run the float path (the content's compiled
// form, its frame read from the server's FkBlocks, which computes 16 frames at
// a time for every stream playing them, then gmr::view_frame_float straight
// into the float encoding); float64 streams, and contents that do not
// compile, the double reference path (gmr::view_frame).
//
// Frame k of the schedule is due at base_time + k / rate (drift-free); the
// server's StreamClock (stream_clock.h) runs every stream's ticks on one timer.
//
// A live stream (set_live) has no timer and no schedule: its source hands it
// each published frame (live_frame), with the content its view shows at that
// frame, and ends it when the source ends. The stream is fed and never calls
// its source back (whoever makes a live stream attaches it to its source).
//
// A slow client costs no computation: a tick whose targets are all congested
// (their clients stopped reading) computes nothing, and the stream then skips
// the ticks of the next kCongestedBackoff at once (each one a drop for each
// target, the sequence numbers advancing so clients see the gap) instead of
// waking at its full rate.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "gmr/server/view.h"
#include "gmr/view/conventions.h"
#include "transport/net.h"

namespace gmr::server {

class LatencyHistogram;

// Where a stream's frames go: a subscription over TCP or over UDP.
class Target {
 public:
  virtual ~Target() = default;
  // False once the target's connection is gone: the stream forgets it.
  virtual bool alive() const = 0;
  // One frame: the shared Frame body (fields >= 16) of stream `stream_id`,
  // whose fan-out began at `made` (the wait a client's frames see from there
  // is counted per connection: WaitHistogram in outbox.h).
  virtual void deliver(std::uint64_t stream_id, const std::shared_ptr<const std::string>& body,
                       std::chrono::steady_clock::time_point made) = 0;
  // True while a frame would only wait behind others the client is not
  // reading: the stream then does not compute one for it.
  virtual bool congested() const { return false; }
  // `n` frames this target did not get because it was congested (counted as drops).
  virtual void skipped(std::uint64_t n) = 0;
  // `n` ticks the stream skipped because the server was late (counted apart).
  virtual void late(std::uint64_t n) = 0;
  // The stream ended this target after `sent` frames ("end of motion",
  // "max_frames reached"); the stream has already forgotten it.
  virtual void ended(std::uint64_t sent, const std::string& reason) = 0;
};

// Stream parameters: beyond these the schedule arithmetic loses meaning (or
// one stream could monopolise the I/O thread).
constexpr double kMinSpeed = 1e-3, kMaxSpeed = 1000.0;
constexpr double kMinRateHz = 1e-2, kMaxRateHz = 10000.0;

class FkBlocks;
class StreamClock;

// The server-wide counters streams add to, and the FK blocks they share.
struct StreamCounters {
  std::uint64_t frames_computed = 0;        // forward-kinematics runs
  std::uint64_t frames_computed_float = 0;  // of those, by the float path
  std::uint64_t frames_encoded = 0;         // encodings (one per tick that sends)
  std::uint64_t frames_skipped = 0;         // ticks skipped because the server was late (per target)
  // Observes how late each tick ran after its due time (seconds); may be null.
  LatencyHistogram* tick_lateness = nullptr;
  // The float path's FK, kept 16 frames at a time (fk_blocks.h); null: each
  // frame computed on its own.
  FkBlocks* fk_blocks = nullptr;
};

class Stream : public std::enable_shared_from_this<Stream> {
 public:
  struct Schedule {
    std::uint32_t start = 0;
    std::uint32_t end = 0;  // exclusive
    bool loop = false;
    double speed = 1.0;
    double rate = 0.0;
    bool skip_repeats = false;
  };
  struct Settings {
    std::vector<int> joints;  // sent, in this order
    bool orientations = false;
    bool local_transforms = false;  // each joint's rotation and translation relative to its parent
    bool float64 = false;
    OutputBasis basis;  // the subscriber's conventions
    Schedule schedule;
    std::chrono::milliseconds max_catch_up{250};
  };
  static constexpr std::chrono::milliseconds kCongestedBackoff{20};

  Stream(StreamClock& clock, std::uint64_t id, std::shared_ptr<const ViewContent> content, Settings settings,
         StreamCounters& counters);

  std::uint64_t id() const { return id_; }
  const Schedule& schedule() const { return settings_.schedule; }
  bool paused() const { return paused_; }
  bool idle() const { return targets_.empty(); }
  std::size_t target_count() const { return targets_.size(); }
  // The key under which the registry lets others join; empty: not joinable.
  const std::string& share_key() const { return share_key_; }
  void set_share_key(std::string key) { share_key_ = std::move(key); }

  // A target starts (or stops) getting this stream's frames; max_frames: it
  // ends after that many (0: no limit).
  void add(std::shared_ptr<Target> target, std::uint64_t max_frames);
  void remove(const Target* target);

  void start();
  // Starts held at the schedule's first frame: that frame goes to the
  // targets once, on the clock's next pass (after the reply that asked for
  // it), then nothing until resume(). A live stream sends nothing.
  void start_paused();
  void pause();
  void resume();
  void seek(std::uint32_t frame);
  void stop() { ++armed_; }  // its tick waiting on the clock, if any, is cancelled
  // The clock's call for tick `generation` (a cancelled one does nothing).
  void on_clock(std::uint64_t generation) {
    if (generation == armed_) on_tick();
  }
  void set_content(std::shared_ptr<const ViewContent> content, std::vector<int> joints, const OutputBasis& basis);
  const std::shared_ptr<const ViewContent>& content() const { return content_; }

  // Live: frames come from a source's live_frame calls instead of a timer.
  void set_live() { live_ = true; }
  bool live() const { return live_; }
  // The source's frame `index`, as `content` (this stream's view at that frame).
  // A frame at or before one this stream already sent is ignored: a joiner's
  // newest frame (send_newest) may cross that same frame's fan-out.
  void live_frame(std::shared_ptr<const ViewContent> content, std::uint64_t index);
  // A frame this stream's view could not be computed for: a gap for its subscribers.
  void live_skipped();
  // The source ended, or the library motion changed: every target ends with `reason`.
  void end_targets(const std::string& reason);
  // A copy of this stream (content, settings, position, sequence) that takes
  // `target` over from it, so the target sees no gap or restart. A live
  // stream's copy is live too, and is to be attached to the same source.
  std::shared_ptr<Stream> split_off(std::uint64_t id, const Target* target);

 private:
  struct Entry {
    std::shared_ptr<Target> target;
    std::uint64_t sent = 0;
    std::uint64_t max_frames = 0;
  };

  double step() const;
  double position(std::uint64_t tick) const;
  Clock::duration period() const;
  // Position `pos` is due at the clock's start_at(now): its rate's next point in turn.
  void rebase(double pos);
  Clock::time_point due(std::uint64_t tick) const;
  // The frame at position `pos`; none past the end of a range that does not loop.
  std::optional<std::uint64_t> frame_at(double pos) const;
  void arm();
  void on_tick();
  // Paused: the frame it holds, once (start_paused).
  void send_still();
  // Frame `frame`, which clients are told is `index`, to the targets that
  // take it now (the others count a skip), outside the clock's ticks (a live
  // frame, a still); false when none took it.
  bool send_one(std::uint64_t frame, std::uint64_t index);
  // Each target got one more frame: those at their max_frames end, the dead go.
  void count_one_sent();
  // Ticks to skip after one that no target could take.
  std::uint64_t congested_ticks() const;
  // Computes and encodes frame `frame` of the content's motion (the shared
  // body), which clients are told is frame `index`.
  std::shared_ptr<const std::string> encode(std::uint64_t frame, std::uint64_t index);
  // ready_[i]: target i is alive and takes a frame now; true when any does.
  bool mark_ready(const std::vector<Entry>& targets);
  // `body` to the ready targets (the others that are alive count a skip),
  // starting one further each time; `made`: now, the frame's fan-out time.
  void fan_out(const std::vector<Entry>& targets, const std::shared_ptr<const std::string>& body,
               Clock::time_point made);

  StreamClock& clock_;
  std::uint64_t id_;
  std::shared_ptr<const ViewContent> content_;
  std::vector<int> own_frames_;  // own_frame_sources of content_'s motion, when local_transforms
  Settings settings_;
  StreamCounters& counters_;
  std::uint64_t armed_ = 0;  // the generation of its tick waiting on the clock
  std::vector<Entry> targets_;
  // targets_ as a tick (or a live frame) found them, which it goes through:
  // a target may end a subscription re-entrantly. Kept between ticks, empty,
  // so a tick allocates nothing for it.
  std::vector<Entry> visiting_;
  std::string share_key_;

  Clock::time_point base_time_{};
  std::uint64_t base_tick_ = 0;
  double base_pos_ = 0.0;
  std::uint64_t tick_ = 0;
  bool paused_ = false;
  double pause_pos_ = 0.0;
  std::int64_t last_frame_ = -1;
  std::uint64_t sequence_ = 0;

  bool live_ = false;
  std::uint64_t live_next_ = 0;      // the lowest source index not sent yet
  std::uint32_t fan_out_start_ = 0;  // rotates: each tick the fan-out starts one target further
  std::vector<char> ready_;          // per target, this tick: alive and not congested
  std::vector<char> alive_;          // per target, this tick: alive
  bool saw_dead_ = true;             // a target was found gone this tick (or it is not known)
};

}  // namespace gmr::server
