#include "stream.h"

#include <cmath>

#include "gmr/wire/frame_encoding.h"
#include "session.h"

namespace gmr::server {

void Stream::on_tick() {
  if (paused_ || targets_.empty()) return;
  const Motion& m = *content_->motion;
  const double pos = position(tick_);
  const double length = static_cast<double>(schedule_.end - schedule_.start);
  std::vector<std::pair<std::weak_ptr<Session>, std::uint32_t>> ended;
  bool finished = false;
  double p = pos;
  if (schedule_.loop) {
    p = std::fmod(pos, length);
    if (p < 0) p += length;
  } else if (pos >= length - 1e-9) {
    finished = true;
  }
  if (!finished) {
    const auto offset = std::min<std::uint64_t>(static_cast<std::uint64_t>(std::floor(p + 1e-9)),
                                                static_cast<std::uint64_t>(length) - 1);
    const std::uint64_t frame = schedule_.start + offset;
    if (!(schedule_.skip_repeats && static_cast<std::int64_t>(frame) == last_frame_)) {
      last_frame_ = static_cast<std::int64_t>(frame);
      const std::size_t n = m.skeleton.size();
      all_positions_.resize(n);
      all_orientations_.resize(orientations_ ? n : 0);
      // One place decides the path: float32 streams the float path, float64 the double one.
      const FramePath path =
          compute_stream_frame(*content_, frame, !float64_, float_buffers_, all_positions_, all_orientations_);
      ++impl_.frames_computed;
      if (path == FramePath::kFloat) ++impl_.frames_computed_float;
      positions_.clear();
      quaternions_.clear();
      for (int j : joints_) {
        positions_.push_back(all_positions_[static_cast<std::size_t>(j)]);
        if (orientations_) quaternions_.emplace_back(all_orientations_[static_cast<std::size_t>(j)]);
      }
      wire::FrameContent c;
      c.skeleton_version = content_->skeleton_version;
      c.frame_index = frame;
      c.motion_time = static_cast<double>(frame) * m.frame_time;
      c.sequence = sequence_++;
      c.server_send_time_ns = now_ns();
      c.positions = positions_;
      c.orientations = quaternions_;
      c.float64 = float64_;
      auto body = std::make_shared<const std::string>(wire::encode_frame_body(c));
      ++impl_.frames_encoded;
      // Copy the targets first: a session may end a subscription re-entrantly.
      auto targets = targets_;
      for (auto& t : targets) {
        auto s = t.session.lock();
        if (!s || s->stopped()) continue;
        s->push_frame(t.subscription_id, t.view_id, id_, body, t.udp);
      }
      for (auto& t : targets_) {
        ++t.sent;
        if (t.max_frames != 0 && t.sent >= t.max_frames) ended.emplace_back(t.session, t.subscription_id);
      }
    }
  } else {
    for (auto& t : targets_) ended.emplace_back(t.session, t.subscription_id);
  }
  ++tick_;
  // Drift-free: the next tick is due at base + k/rate, so a late tick is
  // followed by the ones it delayed (no frame lost to scheduling jitter).
  // Only when the server fell far behind (a stall) does playback jump to the
  // tick due now rather than burst through the backlog.
  const auto now = Clock::now();
  if (due(tick_) + std::max<Clock::duration>(period(), impl_.cfg.max_catch_up) < now) {
    const double behind = std::chrono::duration<double>(now - base_time_).count() * schedule_.rate;
    tick_ = std::max(tick_, base_tick_ + static_cast<std::uint64_t>(behind));
  }
  auto self = shared_from_this();  // sessions may drop the last reference below
  for (auto& [weak, sub] : ended) {
    const auto it = std::find_if(targets_.begin(), targets_.end(),
                                 [&](const Target& t) { return t.subscription_id == sub && !t.session.owner_before(weak) && !weak.owner_before(t.session); });
    const std::uint64_t sent = it != targets_.end() ? it->sent : 0;
    if (auto s = weak.lock()) s->subscription_ended(sub, sent, finished ? "end of motion" : "max_frames reached");
  }
  std::erase_if(targets_, [](const Target& t) { return t.session.expired(); });
  if (!targets_.empty() && !finished) arm();
}

}  // namespace gmr::server
