#include "streams/stream.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/view/engine_pose.h"
#include "gmr/view/viewpoint.h"
#include "gmr/wire/frames.h"
#include "streams/fk_blocks.h"
#include "prometheus/histogram.h"

namespace gmr::server {

Stream::Stream(net::io_context& io, std::uint64_t id, std::shared_ptr<const ViewContent> content, Settings settings,
               StreamCounters& counters)
    : io_(io), id_(id), content_(std::move(content)), settings_(std::move(settings)), counters_(counters), timer_(io) {
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
void Stream::rebase(Clock::time_point now, double pos) {
  base_time_ = now;
  base_pos_ = pos;
  base_tick_ = tick_;
}
Clock::time_point Stream::due(std::uint64_t tick) const {
  return base_time_ + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(
                          static_cast<double>(tick - base_tick_) / settings_.schedule.rate));
}

void Stream::arm() {
  if (live_) return;  // its source's frames drive it
  timer_.expires_at(due(tick_));
  timer_.async_wait([weak = weak_from_this()](const boost::system::error_code& ec) {
    if (ec) return;
    if (auto self = weak.lock()) self->on_tick();
  });
}

void Stream::start() {
  if (live_) return;  // its source's frames drive it
  rebase(Clock::now(), 0.0);
  arm();
}

void Stream::pause() {
  if (paused_) return;
  paused_ = true;
  pause_pos_ = position(tick_);
  timer_.cancel();
}

void Stream::resume() {
  if (!paused_) return;
  paused_ = false;
  if (live_) return;
  rebase(Clock::now(), pause_pos_);
  arm();
}

void Stream::seek(std::uint32_t frame) {
  const double pos = static_cast<double>(frame - settings_.schedule.start);
  last_frame_ = -1;
  if (paused_) {
    pause_pos_ = pos;
    return;
  }
  timer_.cancel();
  rebase(Clock::now(), pos);
  arm();
}

void Stream::set_content(std::shared_ptr<const ViewContent> content, std::vector<int> joints) {
  content_ = std::move(content);
  settings_.joints = std::move(joints);
  if (settings_.local_transforms) own_frames_ = own_frame_sources(*content_->motion);
  last_frame_ = -1;
}

std::shared_ptr<Stream> Stream::split_off(std::uint64_t id, const Target* target) {
  auto s = std::make_shared<Stream>(io_, id, content_, settings_, counters_);
  s->sequence_ = sequence_;  // the subscriber sees no gap or restart
  s->live_ = live_;
  s->last_frame_ = last_frame_;
  s->paused_ = paused_;
  const double pos = paused_ ? pause_pos_ : position(tick_);
  s->pause_pos_ = pos;
  if (!paused_) {
    s->rebase(Clock::now(), pos);
    s->arm();
  }
  auto it = std::find_if(targets_.begin(), targets_.end(), [&](const Entry& e) { return e.target.get() == target; });
  if (it != targets_.end()) {
    s->targets_.push_back(*it);
    targets_.erase(it);
  }
  return s;
}

namespace {

// What encode() computes a frame in: used only inside one encode() call, so
// every stream of a thread shares one set (and it stays in cache) instead of
// each stream keeping its own (the FK workspace alone is ~23 KB for a CMU
// skeleton). Grows to the largest content shown.
struct Scratch {
  std::vector<Eigen::Vector3d> all_positions;  // double path
  std::vector<Eigen::Matrix3d> all_orientations;
  std::vector<double> positions_f64, orientations_f64;
  std::vector<float> workspace;  // float path
  std::vector<float> positions_f32, orientations_f32;
  std::vector<Eigen::Quaterniond> local_rotations;  // local transforms
  std::vector<Eigen::Vector3d> local_translations;
  std::vector<double> local_rotations_f64, local_translations_f64;
  std::vector<float> local_rotations_f32, local_translations_f32;
};

Scratch& scratch() {
  static thread_local Scratch s;
  return s;
}

// For streams made without the server's FkBlocks (each frame computed alone).
FkBlocks& unkept_blocks() {
  static thread_local FkBlocks none(0);
  return none;
}

// The local transforms of `joints` from every joint's pose in w.all_*, as
// float64 and float32 values.
void encode_locals(const Skeleton& skeleton, std::span<const int> own_frames, std::span<const int> joints, Scratch& w) {
  w.local_rotations.resize(joints.size());
  w.local_translations.resize(joints.size());
  engine_locals(skeleton, own_frames, w.all_positions, w.all_orientations, joints, w.local_rotations,
                w.local_translations);
  w.local_rotations_f64.clear();
  w.local_translations_f64.clear();
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const auto& q = w.local_rotations[i];
    const auto& t = w.local_translations[i];
    w.local_rotations_f64.insert(w.local_rotations_f64.end(), {q.x(), q.y(), q.z(), q.w()});
    w.local_translations_f64.insert(w.local_translations_f64.end(), {t.x(), t.y(), t.z()});
  }
  w.local_rotations_f32.assign(w.local_rotations_f64.begin(), w.local_rotations_f64.end());
  w.local_translations_f32.assign(w.local_translations_f64.begin(), w.local_translations_f64.end());
}

}  // namespace

std::shared_ptr<const std::string> Stream::encode(std::uint64_t frame, std::uint64_t index) {
  Scratch& w = scratch();
  const Motion& m = *content_->motion;
  const std::size_t n = m.skeleton.size();
  const int viewer = content_->relative_to;
  const std::vector<int>& joints = settings_.joints;
  wire::FrameContent c;
  c.skeleton_version = content_->skeleton_version;
  c.frame_index = index;
  c.motion_time = static_cast<double>(index) * m.frame_time;
  c.sequence = sequence_++;
  c.float64 = settings_.float64;

  // The float path: FK in float, the viewpoint and quaternions computed from
  // its output and rounded once, straight into what the encoder sends.
  const fast::CompiledMotion* cm = !settings_.float64 && content_->compiled ? content_->compiled->get() : nullptr;
  bool done = false;
  if (cm != nullptr && cm->joint_count() == n && frame < cm->frame_count() && viewer < static_cast<int>(n)) {
    // The viewer's orientation is needed even when the client wants none.
    const bool orient = settings_.orientations || viewer >= 0 || settings_.local_transforms;
    w.workspace.resize(std::max(w.workspace.size(), content_->compiled->workspace_floats()));
    FkBlocks& blocks = counters_.fk_blocks != nullptr ? *counters_.fk_blocks : unkept_blocks();
    if (const auto pose = blocks.frame(content_->compiled, frame, orient, w.workspace)) {
      const std::span<const float> fk_positions = pose->positions, fk_orientations = pose->orientations;
      w.positions_f32.resize(joints.size() * 3);
      w.orientations_f32.resize(settings_.orientations ? joints.size() * 4 : 0);
      view_frame_float(fk_positions, fk_orientations, viewer, joints, w.positions_f32, w.orientations_f32,
                       settings_.basis);
      c.positions = w.positions_f32;
      c.orientations = w.orientations_f32;
      if (settings_.local_transforms) {
        // Every joint's pose in double (a joint's parent and own frame may
        // not be among those sent), then the locals of those sent.
        w.all_positions.resize(n);
        w.all_orientations.resize(n);
        const Viewpoint from =
            viewer < 0 ? Viewpoint() : Viewpoint::of_joint(fk_positions, fk_orientations, static_cast<std::size_t>(viewer));
        for (std::size_t j = 0; j < n; ++j) {
          const float* p = fk_positions.data() + 3 * j;
          const float* o = fk_orientations.data() + 9 * j;
          Eigen::Matrix3d r;
          r << o[0], o[1], o[2], o[3], o[4], o[5], o[6], o[7], o[8];
          w.all_positions[j] = settings_.basis.position(from.position(Eigen::Vector3d(p[0], p[1], p[2])));
          w.all_orientations[j] = settings_.basis.orientation(from.orientation(r));
        }
        encode_locals(m.skeleton, own_frames_, joints, w);
        c.local_rotations = w.local_rotations_f32;
        c.local_translations = w.local_translations_f32;
      }
      ++counters_.frames_computed_float;
      done = true;
    }
  }
  if (!done) {
    w.all_positions.resize(n);
    w.all_orientations.resize(settings_.orientations || viewer >= 0 || settings_.local_transforms ? n : 0);
    view_frame(m, viewer, frame, w.all_positions, w.all_orientations, settings_.basis);
    if (settings_.local_transforms) encode_locals(m.skeleton, own_frames_, joints, w);
    w.positions_f64.clear();
    w.orientations_f64.clear();
    for (int j : joints) {
      const auto& p = w.all_positions[static_cast<std::size_t>(j)];
      w.positions_f64.insert(w.positions_f64.end(), {p.x(), p.y(), p.z()});
      if (settings_.orientations) {
        const Eigen::Quaterniond q(w.all_orientations[static_cast<std::size_t>(j)]);
        w.orientations_f64.insert(w.orientations_f64.end(), {q.x(), q.y(), q.z(), q.w()});
      }
    }
    if (settings_.float64) {
      c.positions_f64 = w.positions_f64;
      c.orientations_f64 = w.orientations_f64;
      if (settings_.local_transforms) {
        c.local_rotations_f64 = w.local_rotations_f64;
        c.local_translations_f64 = w.local_translations_f64;
      }
    } else {  // a float32 stream whose motion did not compile: rounded once here
      w.positions_f32.assign(w.positions_f64.begin(), w.positions_f64.end());
      w.orientations_f32.assign(w.orientations_f64.begin(), w.orientations_f64.end());
      c.positions = w.positions_f32;
      c.orientations = w.orientations_f32;
      if (settings_.local_transforms) {
        c.local_rotations = w.local_rotations_f32;
        c.local_translations = w.local_translations_f32;
      }
    }
  }
  ++counters_.frames_computed;
  c.server_send_time_ns = now_ns();
  auto body = std::make_shared<const std::string>(wire::encode_frame_body(c));
  ++counters_.frames_encoded;
  return body;
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

void Stream::fan_out(const std::vector<Entry>& targets, const std::shared_ptr<const std::string>& body) {
  // The fan-out starts one target further each tick: waiting behind the
  // others' sends is shared by all of a shared stream's subscribers rather
  // than always borne by the last ones.
  const std::size_t n = targets.size();
  const std::size_t first = fan_out_start_++ % n;
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t i = first + k < n ? first + k : first + k - n;
    if (ready_[i]) {
      targets[i].target->deliver(id_, body);
    } else if (alive_[i]) {
      targets[i].target->skipped(1);
    }
  }
}

void Stream::on_tick() {
  if (paused_ || targets_.empty()) return;
  saw_dead_ = true;  // not known until mark_ready() runs
  if (counters_.tick_lateness != nullptr) {
    counters_.tick_lateness->Observe(std::chrono::duration<double>(Clock::now() - due(tick_)).count());
  }
  const Schedule& sched = settings_.schedule;
  const double pos = position(tick_);
  const double length = static_cast<double>(sched.end - sched.start);
  std::vector<std::pair<std::shared_ptr<Target>, std::uint64_t>> ended;
  bool finished = false;
  double p = pos;
  if (sched.loop) {
    p = std::fmod(pos, length);
    if (p < 0) p += length;
  } else if (pos >= length - 1e-9) {
    finished = true;
  }
  if (!finished) {
    const auto offset = std::min<std::uint64_t>(static_cast<std::uint64_t>(std::floor(p + 1e-9)),
                                                static_cast<std::uint64_t>(length) - 1);
    const std::uint64_t frame = sched.start + offset;
    if (!(sched.skip_repeats && static_cast<std::int64_t>(frame) == last_frame_)) {
      // Copy the targets first: a target may end a subscription re-entrantly.
      const auto targets = targets_;
      std::uint64_t ticks = 1;  // this one, and when nobody takes frames the skipped ones after it
      if (mark_ready(targets)) {
        last_frame_ = static_cast<std::int64_t>(frame);
        fan_out(targets, encode(frame, frame));
      } else {
        ticks += congested_ticks();
        sequence_ += ticks;
        for (std::size_t i = 0; i < targets.size(); ++i) {
          if (alive_[i]) targets[i].target->skipped(ticks);
        }
        tick_ += ticks - 1;
      }
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
  const auto now = Clock::now();
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
  content_ = std::move(content);
  if (paused_ || targets_.empty()) return;
  // Copy the targets first: a target may end a subscription re-entrantly.
  const auto targets = targets_;
  if (mark_ready(targets)) {
    fan_out(targets, encode(0, index));
  } else {
    ++sequence_;
    for (std::size_t i = 0; i < targets.size(); ++i) {
      if (alive_[i]) targets[i].target->skipped(1);
    }
  }
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

void Stream::live_ended(const std::string& reason) {
  auto self = shared_from_this();  // ending targets may drop the last reference below
  const auto targets = std::move(targets_);
  targets_.clear();
  for (const auto& e : targets) {
    if (e.target->alive()) e.target->ended(e.sent, reason);
  }
}

}  // namespace gmr::server
