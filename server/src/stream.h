// A stream: one schedule and one content, fanned out to its targets (the
// subscriptions of one or more sessions). Per tick: one forward-kinematics
// pass, one encoding, the same bytes for every target.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "gmr/server/view.h"
#include "server_impl.h"

namespace gmr::server {

// Stream: one schedule, one content; one FK and one encoding per tick, fanned
// out to every target. Float32 streams compute with the float path
// (compute_stream_frame), float64 ones with the double reference path. Frame k of the schedule is due at base_time + k/rate.
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
  struct Target {
    std::weak_ptr<Session> session;
    std::uint32_t subscription_id = 0;
    std::uint32_t view_id = 0;
    bool udp = false;
    std::uint64_t sent = 0;
    std::uint64_t max_frames = 0;
  };

  Stream(Server::Impl& impl, std::uint64_t id, std::shared_ptr<const ViewContent> content, std::vector<int> joints,
         bool orientations, bool float64, Schedule schedule)
      : impl_(impl), id_(id), content_(std::move(content)), joints_(std::move(joints)), orientations_(orientations),
        float64_(float64), schedule_(schedule), timer_(impl.io) {}

  std::uint64_t id() const { return id_; }
  std::string key;  // non-empty while it can be joined by a shared subscription
  const std::vector<int>& joints() const { return joints_; }
  const Schedule& schedule() const { return schedule_; }
  bool paused() const { return paused_; }
  std::vector<Target>& targets() { return targets_; }

  void start() {
    rebase(Clock::now(), 0.0);
    arm();
  }
  void pause() {
    if (paused_) return;
    paused_ = true;
    pause_pos_ = position(tick_);
    timer_.cancel();
  }
  void resume() {
    if (!paused_) return;
    paused_ = false;
    rebase(Clock::now(), pause_pos_);
    arm();
  }
  void seek(std::uint32_t frame) {
    const double pos = static_cast<double>(frame - schedule_.start);
    last_frame_ = -1;
    if (paused_) {
      pause_pos_ = pos;
      return;
    }
    timer_.cancel();
    rebase(Clock::now(), pos);
    arm();
  }
  void set_content(std::shared_ptr<const ViewContent> content, std::vector<int> joints) {
    content_ = std::move(content);
    joints_ = std::move(joints);
    last_frame_ = -1;
  }
  // A copy of this stream's content and position for one target leaving it.
  std::shared_ptr<Stream> clone(std::uint64_t id) const {
    auto s = std::make_shared<Stream>(impl_, id, content_, joints_, orientations_, float64_, schedule_);
    s->sequence_ = sequence_;  // the subscriber sees no gap or restart
    s->last_frame_ = last_frame_;
    s->paused_ = paused_;
    const double pos = paused_ ? pause_pos_ : position(tick_);
    s->pause_pos_ = pos;
    if (!paused_) {
      s->rebase(Clock::now(), pos);
      s->arm();
    }
    return s;
  }
  void stop() { timer_.cancel(); }

 private:
  double step() const { return schedule_.speed / (schedule_.rate * content_->motion->frame_time); }
  double position(std::uint64_t tick) const { return base_pos_ + static_cast<double>(tick - base_tick_) * step(); }
  std::chrono::steady_clock::duration period() const {
    return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / schedule_.rate));
  }
  void rebase(Clock::time_point now, double pos) {
    base_time_ = now;
    base_pos_ = pos;
    base_tick_ = tick_;
  }
  Clock::time_point due(std::uint64_t tick) const {
    return base_time_ + std::chrono::duration_cast<Clock::duration>(
                            std::chrono::duration<double>(static_cast<double>(tick - base_tick_) / schedule_.rate));
  }
  void arm() {
    timer_.expires_at(due(tick_));
    timer_.async_wait([weak = weak_from_this()](const boost::system::error_code& ec) {
      if (ec) return;
      if (auto self = weak.lock()) self->on_tick();
    });
  }
  void on_tick();

  Server::Impl& impl_;
  std::uint64_t id_;
  std::shared_ptr<const ViewContent> content_;
  std::vector<int> joints_;
  bool orientations_;
  bool float64_;
  Schedule schedule_;
  net::steady_timer timer_;
  std::vector<Target> targets_;

  Clock::time_point base_time_{};
  std::uint64_t base_tick_ = 0;
  double base_pos_ = 0.0;
  std::uint64_t tick_ = 0;
  bool paused_ = false;
  double pause_pos_ = 0.0;
  std::int64_t last_frame_ = -1;
  std::uint64_t sequence_ = 0;

  std::vector<Eigen::Vector3d> all_positions_;
  std::vector<Eigen::Matrix3d> all_orientations_;
  std::vector<Eigen::Vector3d> positions_;
  std::vector<Eigen::Quaterniond> quaternions_;
  FloatFrameBuffers float_buffers_;  // float32 streams: the float path's outputs and workspace
};

}  // namespace gmr::server
