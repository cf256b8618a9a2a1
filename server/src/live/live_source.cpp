#include "live/live_source.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <algorithm>
#include <unordered_map>
#include <utility>

#include "streams/stream.h"

namespace gmr::server {

namespace {

Result<std::shared_ptr<const Motion>> replay(const std::vector<LiveStep>& steps, std::shared_ptr<const Motion> m) {
  for (const auto& step : steps) {
    auto next = step(*m);
    if (!next.ok()) return next.error();
    m = std::make_shared<const Motion>(std::move(next).value());
  }
  return m;
}

// A live stream's content at one frame: its view's, showing `motion`.
std::shared_ptr<const ViewContent> at_frame(const ViewContent& content, std::shared_ptr<const Motion> motion) {
  auto next = std::make_shared<ViewContent>(content);
  next->motion = std::move(motion);
  next->compiled = nullptr;
  return next;
}

}  // namespace

bool LiveSource::shows(const ViewContent& content, const ReplayGroup& g) {
  const ViewContent& first = *g.content;
  if (content.live_steps == first.live_steps) return true;
  return content.live_key && first.live_key && content.live_key_hash == first.live_key_hash &&
         *content.live_key == *first.live_key;
}

LiveSource::LiveSource(std::string name, std::uint64_t serial, Skeleton skeleton, double frame_time,
                       double metres_per_unit)
    : name_(std::move(name)),
      serial_(serial),
      frame_time_(frame_time),
      metres_per_unit_(metres_per_unit),
      hold_(1.0 / frame_time, Clock::now()) {
  auto m = std::make_shared<Motion>();
  m->skeleton = std::move(skeleton);
  m->convention = Convention::kPreRotation;
  m->frame_time = frame_time;
  m->frame_count = 1;
  m->values.assign(m->stride(), 0.0);
  latest_ = std::move(m);
}

std::uint64_t LiveSource::held_bytes(const Skeleton& skeleton) {
  std::uint64_t bytes = 0;
  for (const Joint& j : skeleton.joints()) {
    // The joint, its name and channels, and the index entries per joint.
    bytes += sizeof(Joint) + j.name.size() + j.channels.size() * sizeof(ChannelType) + 8 * sizeof(int);
  }
  bytes += static_cast<std::uint64_t>(skeleton.channel_count()) * sizeof(double);
  // The newest frame's motion carries a skeleton of its own, as does the
  // frame being made, and the skeleton's indexes: 4,096 joints measured at
  // about 2.5 MB of RSS per source, which this gives.
  return 4 * bytes;
}

Result<LiveSource::Pushed> LiveSource::push(std::span<const double> values, std::optional<std::uint64_t> index_given,
                                            Clock::time_point now) {
  if (ended_) return make_error("the live source '" + name_ + "' has ended");
  if (index_given && *index_given < frames_) {
    return make_error("frame " + std::to_string(*index_given) + " came after frame " + std::to_string(frames_ - 1));
  }
  // A replica that joins a running source takes its first frame's number
  // as it comes; after that the numbers may skip at most kMaxIndexGap.
  if (index_given && frames_ > 0 && *index_given - frames_ > kMaxIndexGap) {
    return make_error("frame " + std::to_string(*index_given) + " would skip " +
                      std::to_string(*index_given - frames_) + " frames after frame " + std::to_string(frames_) +
                      "; at most " + std::to_string(kMaxIndexGap) + " may be missing at once");
  }
  const Skeleton& sk = latest_->skeleton;
  const std::size_t stride = latest_->stride();
  if (values.size() != stride) {
    return make_error("frame " + std::to_string(frames_) + " has " + std::to_string(values.size()) +
                      " values; the skeleton of '" + name_ + "' has " + std::to_string(stride) + " channels");
  }
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (std::isfinite(values[i])) continue;
    // Which joint's channel, for the message.
    int joint = 0;
    while (joint + 1 < static_cast<int>(sk.size()) && static_cast<std::size_t>(sk.channel_offset(joint + 1)) <= i) {
      ++joint;
    }
    return make_error("frame " + std::to_string(frames_) + ": value " + std::to_string(i) + " (joint '" +
                      sk.joint(joint).name + "', channel " +
                      std::to_string(i - static_cast<std::size_t>(sk.channel_offset(joint))) + ") is not finite");
  }
  if (!hold_.take(now)) {
    ++over_rate_;
    return Pushed::kOverRate;
  }
  auto m = std::make_shared<Motion>();
  m->skeleton = sk;
  m->convention = Convention::kPreRotation;
  m->frame_time = frame_time_;
  m->frame_count = 1;
  m->values.assign(values.begin(), values.end());
  latest_ = std::move(m);
  if (index_given) frames_ = *index_given;
  const std::uint64_t index = frames_++;
  if (recording_) recording_->add(values);

  // Unedited views get the frame now; each distinct edit list is replayed
  // once per frame, whatever the number of streams showing it.
  // The streams are gathered first: handing one a frame may end
  // subscriptions, which must not touch the list being walked.
  std::vector<std::shared_ptr<Stream>> streams;
  streams.reserve(streams_.size());
  std::erase_if(streams_, [&](const std::weak_ptr<Stream>& w) {
    auto s = w.lock();
    if (!s || s->idle()) return true;
    streams.push_back(std::move(s));
    return false;
  });
  ReplayBatch batch{index, latest_, {}};
  std::unordered_map<std::size_t, std::vector<std::size_t>> groups_by_hash;
  for (const auto& s : streams) {
    auto content = s->content();
    if (!content->live_steps || content->live_steps->empty()) {
      s->live_frame(at_frame(*content, latest_), index);
      continue;
    }
    auto& candidates = groups_by_hash[content->live_key_hash];
    const auto same = std::ranges::find_if(candidates, [&](std::size_t g) { return shows(*content, batch.groups[g]); });
    if (same != candidates.end()) {
      batch.groups[*same].streams.push_back(s);
      continue;
    }
    candidates.push_back(batch.groups.size());
    batch.groups.push_back(ReplayGroup{std::move(content), {s}});
  }
  if (batch.groups.empty()) return Pushed::kSent;
  if (!replay_work_) {
    for (auto& g : batch.groups) {
      g.made = replay(*g.content->live_steps, latest_);
      deliver(g, index, 0);
    }
    if (replays_total_) *replays_total_ += batch.groups.size();
  } else if (replaying_) {
    // The frame waits for the batch under way; with the queue full, the
    // oldest waiting one is skipped by its streams.
    if (replay_next_.size() >= kReplayQueue) {
      const std::uint64_t dropped = replay_next_.front().skipped_before + 1;
      replay_next_.pop_front();
      (replay_next_.empty() ? batch : replay_next_.front()).skipped_before += dropped;
    }
    replay_next_.push_back(std::move(batch));
  } else {
    start_replay(std::move(batch));
  }
  return Pushed::kSent;
}

void LiveSource::set_replay(net::any_io_executor work, net::any_io_executor home) {
  replay_work_ = std::move(work);
  replay_home_ = std::move(home);
}

void LiveSource::skip(const ReplayBatch& batch) {
  for (const auto& g : batch.groups) {
    for (const auto& w : g.streams) {
      auto s = w.lock();
      for (std::uint64_t k = 0; s && k <= batch.skipped_before; ++k) s->live_skipped();
    }
  }
}

void LiveSource::start_replay(ReplayBatch batch) {
  replaying_ = true;
  net::post(*replay_work_, [self = shared_from_this(), batch = std::move(batch)]() mutable {
    // The replay thread: only the batch (its own motions, the edit lists'
    // functions, which hold no mutable state) is touched here.
    for (auto& g : batch.groups) g.made = replay(*g.content->live_steps, batch.frame);
    net::post(*self->replay_home_,
              [self, batch = std::move(batch)]() mutable { self->finish_replay(std::move(batch)); });
  });
}

void LiveSource::finish_replay(ReplayBatch batch) {
  replaying_ = false;
  if (replays_total_) *replays_total_ += batch.groups.size();
  for (const auto& g : batch.groups) deliver(g, batch.index, batch.skipped_before);
  if (end_reason_) {
    // Ended: what still waits is skipped rather than replayed (a queue of
    // costly replays would hold the end back).
    for (const auto& waiting : replay_next_) skip(waiting);
    replay_next_.clear();
  }
  if (!replay_next_.empty()) {
    auto next = std::move(replay_next_.front());
    replay_next_.pop_front();
    start_replay(std::move(next));
  } else if (end_reason_) {
    tell_ended(std::exchange(end_reason_, std::nullopt).value());
  }
}

void LiveSource::deliver(const ReplayGroup& g, std::uint64_t index, std::uint64_t skipped_before) {
  if (!g.made.ok() && replay_failures_++ % 1000 == 0) {
    spdlog::warn("live '{}': frame {}: a view's edits failed on it, so its subscribers skip it: {}", name_, index,
                 g.made.error().to_string());
  }
  for (const auto& w : g.streams) {
    auto s = w.lock();
    if (!s || s->idle()) continue;
    for (std::uint64_t k = 0; k < skipped_before; ++k) s->live_skipped();
    // A view edited since the replay began shows other edits: it skips this frame.
    if (!g.made.ok() || !shows(*s->content(), g)) {
      s->live_skipped();
      continue;
    }
    s->live_frame(at_frame(*s->content(), g.made.value()), index);
  }
}

void LiveSource::end(const std::string& reason) {
  if (ended_) return;
  ended_ = true;
  if (replaying_) {
    end_reason_ = reason;  // finish_replay tells them
    return;
  }
  tell_ended(reason);
}

void LiveSource::tell_ended(const std::string& reason) {
  auto streams = std::move(streams_);
  streams_.clear();
  for (const auto& w : streams) {
    if (auto s = w.lock()) s->end_targets(reason);
  }
}

void LiveSource::attach(const std::shared_ptr<Stream>& stream) { streams_.push_back(stream); }

void LiveSource::send_newest(Stream& stream) const {
  if (ended_ || frames_ == 0 || stream.paused() || stream.idle()) return;
  auto motion = view_motion(*stream.content());
  if (!motion.ok()) return;  // the next frame will tell (push logs it)
  stream.live_frame(at_frame(*stream.content(), std::move(motion).value()), frames_ - 1);
}

Result<std::shared_ptr<const Motion>> LiveSource::view_motion(const ViewContent& content) const {
  if (!content.live_steps || content.live_steps->empty()) return latest_;
  return replay(*content.live_steps, latest_);
}

}  // namespace gmr::server
