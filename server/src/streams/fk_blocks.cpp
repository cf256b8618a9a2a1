#include "streams/fk_blocks.h"

#include <algorithm>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/server/view.h"

namespace gmr::server {

namespace {

bool same_owner(const std::weak_ptr<const CompiledForm>& a, const std::shared_ptr<const CompiledForm>& b) {
  return !a.owner_before(b) && !b.owner_before(a);
}

// Frame `at` of a block's frame-major positions and (when wanted) orientations.
FkBlocks::Pose pose_at(const std::vector<float>& positions, const std::vector<float>& rotations, std::size_t at,
                       std::size_t joints, bool orientations) {
  return {
      std::span<const float>(positions).subspan(at * joints * 3, joints * 3),
      orientations ? std::span<const float>(rotations).subspan(at * joints * 9, joints * 9) : std::span<const float>()};
}

}  // namespace

FkBlocks::List::iterator FkBlocks::make_room(const Key& key, std::size_t bytes_needed) {
  List spare;
  while (!lru_.empty() && bytes_ + bytes_needed > budget_) {
    auto last = std::prev(lru_.end());
    index_.erase(last->key);
    bytes_ -= last->bytes();
    if (spare.empty()) {
      spare.splice(spare.begin(), lru_, last);  // its vectors serve the new block
    } else {
      lru_.erase(last);
    }
  }
  if (spare.empty()) spare.emplace_back();
  lru_.splice(lru_.begin(), spare, spare.begin());
  auto it = lru_.begin();
  it->key = key;
  index_[key] = it;
  return it;
}

std::optional<FkBlocks::Pose> FkBlocks::frame(const std::shared_ptr<const CompiledForm>& form, std::size_t frame,
                                              bool orientations, std::span<float> workspace) {
  const fast::CompiledMotion* cm = form ? form->get() : nullptr;
  if (cm == nullptr || frame >= cm->frame_count()) return std::nullopt;
  const std::size_t joints = cm->joint_count();

  if (budget_ == 0) {
    alone_positions_.resize(joints * 3);
    alone_rotations_.resize(orientations ? joints * 9 : 0);
    fast::FkFrameJob job{cm, frame, alone_positions_, alone_rotations_, workspace};
    if (!job.run()) return std::nullopt;
    ++alone_;
    return Pose{alone_positions_, alone_rotations_};
  }

  const Key key{form.get(), frame / kFrames};
  const std::size_t at = frame % kFrames;
  auto found = index_.find(key);
  if (found != index_.end()) {
    Block& b = *found->second;
    if (same_owner(b.owner, form) && (b.orientations || !orientations)) {
      lru_.splice(lru_.begin(), lru_, found->second);
      ++hits_;
      return pose_at(b.positions, b.rotations, at, joints, orientations);
    }
    // Another motion that took a freed one's address, or orientations now
    // wanted: computed again in place.
    bytes_ -= b.bytes();
    lru_.erase(found->second);
    index_.erase(found);
  }

  const std::size_t begin = key.block * kFrames;
  const std::size_t count = std::min(kFrames, cm->frame_count() - begin);
  const std::size_t need = count * joints * (orientations ? 12 : 3) * sizeof(float);
  if (need > budget_) {
    // A block larger than the whole budget is computed for this frame and not kept.
    alone_positions_.resize(count * joints * 3);
    alone_rotations_.resize(orientations ? count * joints * 9 : 0);
    fast::FkRangeJob job{
        cm, begin, begin + count, fast::Layout::kFrameMajor, 0, alone_positions_, alone_rotations_, workspace};
    if (!job.run()) return std::nullopt;
    ++computed_;
    return pose_at(alone_positions_, alone_rotations_, at, joints, orientations);
  }
  auto it = make_room(key, need);
  Block& b = *it;
  b.owner = form;
  b.orientations = orientations;
  b.positions.resize(count * joints * 3);
  b.rotations.resize(orientations ? count * joints * 9 : 0);
  fast::FkRangeJob job{cm, begin, begin + count, fast::Layout::kFrameMajor, 0, b.positions, b.rotations, workspace};
  if (!job.run()) {
    index_.erase(key);
    lru_.erase(it);
    return std::nullopt;
  }
  ++computed_;
  bytes_ += b.bytes();
  return pose_at(b.positions, b.rotations, at, joints, orientations);
}

}  // namespace gmr::server
