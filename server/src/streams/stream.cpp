#include "streams/stream.h"

#include <algorithm>
#include <cmath>

#include "gmr/view/engine_pose.h"
#include "transport/latency_histogram.h"
#include "streams/frame_encoder.h"
#include "streams/stream_clock.h"

namespace gmr::server {

Stream::Stream(StreamClock& clock, std::uint64_t id, std::shared_ptr<const ViewContent> content, Settings settings,
               StreamCounters& counters)
    : clock_(clock), id_(id), content_(std::move(content)), settings_(std::move(settings)), counters_(counters) {
  if (settings_.local_transforms) own_frames_ = own_frame_sources(*content_->motion);
}

void Stream::add(std::shared_ptr<Target> target, std::uint64_t max_frames) {
  targets_.push_back(Entry{std::move(target), 0, max_frames});
}

void Stream::remove(const Target* target) {
  std::erase_if(targets_, [&](const Entry& e) { return e.target.get() == target; });
}

double Stream::step() const {
  return settings_.schedule.speed / (settings_.schedule.rate * content_->motion->frame_time);
}
double Stream::position(std::uint64_t tick) const {
  return base_pos_ + static_cast<double>(tick - base_tick_) * step();
}
Clock::duration Stream::period() const {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / settings_.schedule.rate));
}
void Stream::rebase(double pos) {
  // On the clock's grid: streams of one rate tick in a few groups, evenly
  // filled (stream_clock.h).
  base_time_ = clock_.start_at(Clock::now(), settings_.schedule.rate);
  base_pos_ = pos;
  base_tick_ = tick_;
}
Clock::time_point Stream::due(std::uint64_t tick) const {
  return base_time_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(
                          static_cast<double>(tick - base_tick_) / settings_.schedule.rate));
}

std::optional<std::uint64_t> Stream::frame_at(double pos) const {
  const Schedule& sched = settings_.schedule;
  const double length = static_cast<double>(sched.end - sched.start);
  double p = pos;
  if (sched.loop) {
    p = std::fmod(pos, length);
    if (p < 0) p += length;
  } else if (pos >= length - 1e-9) {
    return std::nullopt;
  }
  const auto offset =
      std::min<std::uint64_t>(static_cast<std::uint64_t>(std::floor(p + 1e-9)), static_cast<std::uint64_t>(length) - 1);
  return sched.start + offset;
}

void Stream::arm() {
  if (live_) return;  // its source's frames drive it
  clock_.schedule(weak_from_this(), due(tick_), ++armed_);
}

void Stream::start() {
  if (live_) return;  // its source's frames drive it
  rebase(0.0);
  arm();
}

void Stream::start_paused() {
  paused_ = true;
  pause_pos_ = 0.0;
  if (live_) return;  // its source's frames pass it by until it resumes
  clock_.schedule(weak_from_this(), Clock::now(), ++armed_);
}

void Stream::pause() {
  if (paused_) return;
  paused_ = true;
  pause_pos_ = position(tick_);
  stop();
}

void Stream::resume() {
  if (!paused_) return;
  paused_ = false;
  if (live_) return;
  rebase(pause_pos_);
  arm();
}

void Stream::seek(std::uint32_t frame) {
  const double pos = static_cast<double>(frame - settings_.schedule.start);
  last_frame_ = -1;
  if (paused_) {
    pause_pos_ = pos;
    return;
  }
  stop();
  rebase(pos);
  arm();
}

void Stream::set_content(std::shared_ptr<const ViewContent> content, std::vector<int> joints,
                         const OutputBasis& basis) {
  content_ = std::move(content);
  settings_.joints = std::move(joints);
  settings_.basis = basis;
  if (settings_.local_transforms) own_frames_ = own_frame_sources(*content_->motion);
  last_frame_ = -1;
}

std::shared_ptr<Stream> Stream::split_off(std::uint64_t id, const Target* target) {
  auto s = std::make_shared<Stream>(clock_, id, content_, settings_, counters_);
  s->sequence_ = sequence_;  // the subscriber sees no gap or restart
  s->live_ = live_;
  s->live_next_ = live_next_;
  s->last_frame_ = last_frame_;
  s->paused_ = paused_;
  s->pause_pos_ = paused_ ? pause_pos_ : position(tick_);
  if (!paused_) {
    // Its next tick is due when this one's is: the same frame at the same
    // time, in the same group of the clock.
    s->base_time_ = base_time_;
    s->base_pos_ = base_pos_;
    s->base_tick_ = base_tick_;
    s->tick_ = tick_;
    s->arm();
  }
  auto it = std::find_if(targets_.begin(), targets_.end(), [&](const Entry& e) { return e.target.get() == target; });
  if (it != targets_.end()) {
    s->targets_.push_back(*it);
    targets_.erase(it);
  }
  return s;
}

std::shared_ptr<const std::string> Stream::encode(std::uint64_t frame, std::uint64_t index) {
  return encode_frame(*content_, settings_, own_frames_, frame, index, sequence_++, counters_);
}

std::uint64_t Stream::congested_ticks() const {
  // The ticks due before now + kCongestedBackoff, after this one; never past
  // a target's max_frames (it ends on time).
  const double ahead =
      std::chrono::duration<double>(Clock::now() + kCongestedBackoff - base_time_).count() * settings_.schedule.rate;
  const auto last = base_tick_ + static_cast<std::uint64_t>(std::max(0.0, ahead));
  std::uint64_t n = last > tick_ + 1 ? last - tick_ - 1 : 0;
  for (const auto& e : targets_) {
    if (e.max_frames != 0) n = std::min(n, e.max_frames - std::min(e.max_frames, e.sent + 1));
  }
  return n;
}

bool Stream::mark_ready(const std::vector<Entry>& targets) {
  // Each target's liveness is read once a tick (its connection and handler
  // are cold in the cache when a stream has thousands of them).
  ready_.assign(targets.size(), 0);
  alive_.assign(targets.size(), 0);
  saw_dead_ = false;
  bool anyone = false;
  for (std::size_t i = 0; i < targets.size(); ++i) {
    const bool alive = targets[i].target->alive();
    alive_[i] = alive;
    saw_dead_ = saw_dead_ || !alive;
    ready_[i] = alive && !targets[i].target->congested();
    anyone = anyone || ready_[i];
  }
  return anyone;
}

void Stream::fan_out(const std::vector<Entry>& targets, const std::shared_ptr<const std::string>& body,
                     Clock::time_point made) {
  // The fan-out starts one target further each tick: waiting behind the
  // others' sends is shared by all of a shared stream's subscribers rather
  // than always borne by the last ones.
  const std::size_t n = targets.size();
  const std::size_t first = fan_out_start_++ % n;
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t i = first + k < n ? first + k : first + k - n;
    if (ready_[i]) {
      targets[i].target->deliver(id_, body, made);
    } else if (alive_[i]) {
      targets[i].target->skipped(1);
    }
  }
}

void Stream::on_tick() {
  if (targets_.empty()) return;
  if (paused_) {
    send_still();  // pause() cancels a tick it finds waiting: this is start_paused's
    return;
  }
  saw_dead_ = true;  // not known until mark_ready() runs
  // The tick's clock readings: its start, and its fan-out's (after the FK
  // and the encoding), which also serves the catch-up check at its end.
  Clock::time_point now = Clock::now();
  if (counters_.tick_lateness != nullptr) {
    // A tick runs up to StreamClock::kGrain early: on time, for lateness.
    counters_.tick_lateness->observe(now - due(tick_));
  }
  const Schedule& sched = settings_.schedule;
  const std::optional<std::uint64_t> at = frame_at(position(tick_));
  std::vector<std::pair<std::shared_ptr<Target>, std::uint64_t>> ended;
  const bool finished = !at;
  if (!finished) {
    const std::uint64_t frame = *at;
    if (!(sched.skip_repeats && static_cast<std::int64_t>(frame) == last_frame_)) {
      // Copy the targets first: a target may end a subscription re-entrantly.
      visiting_ = targets_;
      const std::vector<Entry>& targets = visiting_;
      std::uint64_t ticks = 1;  // this one, and when nobody takes frames the skipped ones after it
      if (mark_ready(targets)) {
        last_frame_ = static_cast<std::int64_t>(frame);
        const auto body = encode(frame, frame);
        now = Clock::now();
        fan_out(targets, body, now);
      } else {
        ticks += congested_ticks();
        sequence_ += ticks;
        for (std::size_t i = 0; i < targets.size(); ++i) {
          if (alive_[i]) targets[i].target->skipped(ticks);
        }
        tick_ += ticks - 1;
      }
      visiting_.clear();
      for (auto& e : targets_) {
        e.sent += ticks;
        if (e.max_frames != 0 && e.sent >= e.max_frames) ended.emplace_back(e.target, e.sent);
      }
    }
  } else {
    for (const auto& e : targets_) ended.emplace_back(e.target, e.sent);
  }
  ++tick_;
  // Drift-free: the next tick is due at base + k/rate, so a late tick is
  // followed by the ones it delayed (no frame lost to scheduling jitter).
  // Only when the server fell far behind (a stall) does playback jump to the
  // tick due now rather than burst through the backlog.
  // The ticks jumped over are not hidden: sequence numbers advance (clients
  // see the gap) and each target counts them as skipped, apart from drops.
  if (due(tick_) + std::max<Clock::duration>(period(), settings_.max_catch_up) < now) {
    const double behind = std::chrono::duration<double>(now - base_time_).count() * sched.rate;
    const std::uint64_t to = std::max(tick_, base_tick_ + static_cast<std::uint64_t>(behind));
    const std::uint64_t jumped = to - tick_;
    tick_ = to;
    if (jumped > 0 && !finished) {
      sequence_ += jumped;
      for (auto& e : targets_) {
        // A target whose max_frames this tick reached has ended: the ticks
        // after it are not its. Another counts those up to its max_frames.
        if (e.max_frames != 0 && e.sent >= e.max_frames) continue;
        const std::uint64_t n = e.max_frames == 0 ? jumped : std::min(jumped, e.max_frames - e.sent);
        if (e.target->alive()) {
          e.target->late(n);
          counters_.frames_skipped += n;
        }
        e.sent += n;
        if (e.max_frames != 0 && e.sent >= e.max_frames) ended.emplace_back(e.target, e.sent);
      }
    }
  }
  auto self = shared_from_this();  // ending targets may drop the last reference below
  for (auto& [target, sent] : ended) {
    remove(target.get());
    if (target->alive()) target->ended(sent, finished ? "end of motion" : "max_frames reached");
  }
  // The targets found gone; one that goes during this tick is found at the next.
  if (saw_dead_) std::erase_if(targets_, [](const Entry& e) { return !e.target->alive(); });
  if (!targets_.empty() && !finished) arm();
}

void Stream::live_frame(std::shared_ptr<const ViewContent> content, std::uint64_t index) {
  if (index < live_next_) return;
  live_next_ = index + 1;
  content_ = std::move(content);
  if (paused_ || targets_.empty()) return;
  send_one(0, index);
}

void Stream::send_still() {
  // Held past the end of its range: its last frame.
  const std::uint64_t frame = frame_at(pause_pos_).value_or(settings_.schedule.end - 1);
  if (send_one(frame, frame)) last_frame_ = static_cast<std::int64_t>(frame);
}

bool Stream::send_one(std::uint64_t frame, std::uint64_t index) {
  // Copy the targets first: a target may end a subscription re-entrantly.
  visiting_ = targets_;
  const std::vector<Entry>& targets = visiting_;
  const bool sent = mark_ready(targets);
  if (sent) {
    const auto body = encode(frame, index);
    fan_out(targets, body, Clock::now());
  } else {
    ++sequence_;
    for (std::size_t i = 0; i < targets.size(); ++i) {
      if (alive_[i]) targets[i].target->skipped(1);
    }
  }
  visiting_.clear();
  count_one_sent();
  return sent;
}

void Stream::count_one_sent() {
  std::vector<std::pair<std::shared_ptr<Target>, std::uint64_t>> ended;
  for (auto& e : targets_) {
    ++e.sent;
    if (e.max_frames != 0 && e.sent >= e.max_frames) ended.emplace_back(e.target, e.sent);
  }
  auto self = shared_from_this();  // ending targets may drop the last reference below
  for (auto& [target, sent] : ended) {
    remove(target.get());
    if (target->alive()) target->ended(sent, "max_frames reached");
  }
  if (saw_dead_) std::erase_if(targets_, [](const Entry& e) { return !e.target->alive(); });
}

void Stream::live_skipped() {
  if (paused_ || targets_.empty()) return;
  ++sequence_;
  for (auto& e : targets_) {
    if (!e.target->alive()) continue;
    e.target->late(1);
    ++counters_.frames_skipped;
  }
}

void Stream::end_targets(const std::string& reason) {
  auto self = shared_from_this();  // ending targets may drop the last reference below
  const auto targets = std::move(targets_);
  targets_.clear();
  for (const auto& e : targets) {
    if (e.target->alive()) e.target->ended(e.sent, reason);
  }
}

}  // namespace gmr::server
