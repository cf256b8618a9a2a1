#include "live/live_source.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <map>

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
  if (index_given && *index_given - frames_ > kMaxIndexGap) {
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
  if (recording_) {
    if ((recording_->values.size() + values.size()) * sizeof(double) <= record_max_bytes_) {
      recording_->values.insert(recording_->values.end(), values.begin(), values.end());
      ++recording_->frame_count;
    } else if (!record_truncated_) {
      record_truncated_ = true;
      spdlog::warn("live {}: the recording stops at frame {}: {} bytes of values is the limit (--max-record-bytes)",
                   name_, index, record_max_bytes_);
    }
  }

  // Each distinct edit list is replayed once per frame, whatever the number
  // of streams showing it.
  std::vector<std::shared_ptr<Stream>> streams;
  streams.reserve(streams_.size());
  std::erase_if(streams_, [&](const std::weak_ptr<Stream>& w) {
    auto s = w.lock();
    if (!s || s->idle()) return true;
    streams.push_back(std::move(s));
    return false;
  });
  std::map<const std::vector<LiveStep>*, std::shared_ptr<const Motion>> made;
  for (const auto& s : streams) {
    const auto& content = s->content();
    const std::vector<LiveStep>* steps = content->live_steps.get();
    auto it = made.find(steps);
    if (it == made.end()) {
      std::shared_ptr<const Motion> motion = latest_;
      if (steps != nullptr && !steps->empty()) {
        auto r = replay(*steps, latest_);
        if (!r.ok()) {
          if (replay_failures_++ % 1000 == 0) {
            spdlog::warn("live '{}': frame {}: a view's edits failed on it, so its subscribers skip it: {}", name_,
                         index, r.error().to_string());
          }
          motion = nullptr;
        } else {
          motion = std::move(r).value();
        }
      }
      it = made.emplace(steps, std::move(motion)).first;
    }
    if (!it->second) {
      s->live_skipped();
      continue;
    }
    s->live_frame(at_frame(*content, it->second), index);
  }
  return Pushed::kSent;
}

void LiveSource::end(const std::string& reason) {
  if (ended_) return;
  ended_ = true;
  auto streams = std::move(streams_);
  streams_.clear();
  for (const auto& w : streams) {
    if (auto s = w.lock()) s->live_ended(reason);
  }
}

void LiveSource::record(std::size_t max_bytes) {
  recording_ = std::make_unique<Motion>();
  recording_->skeleton = latest_->skeleton;
  recording_->convention = Convention::kPreRotation;
  recording_->frame_time = frame_time_;
  record_max_bytes_ = max_bytes;
}

std::shared_ptr<const Motion> LiveSource::recording(bool* truncated) const {
  if (!recording_ || !ended_) return nullptr;
  if (truncated) *truncated = record_truncated_;
  return std::make_shared<const Motion>(*recording_);
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
