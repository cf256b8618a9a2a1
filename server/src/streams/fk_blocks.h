// FkBlocks: the float forward kinematics of the motions streams play, computed
// 16 frames at a time and kept for every stream that plays those frames.
//
// Streams of one motion each run on their own timer, so on a busy server many
// of them play the same frames a little apart. Computing each frame for each
// stream on its own (gmr::fast::FkFrameJob) costs about 0.24 µs for CMU 01_01,
// more in a server whose per-stream state has left the cache; the range kernel
// (gmr::fast::FkRangeJob) computes 16 consecutive frames at about 76 ns each.
// A stream asking for a frame gets it from the block of 16 that holds it,
// computed when the first stream needs one of its frames: that stream's next
// ticks, and every other stream of the motion in those frames, read it.
//
// Blocks are kept while they fit a byte budget, the least recently used going
// first. Every frame comes from a block, so a frame is the same bits whichever
// stream asks and whether its block was kept or computed again (the range
// kernel's results do not depend on where a frame falls in the range). A block
// holds its motion weakly: a motion no view shows any more is freed, and its
// blocks are never mistaken for those of a motion later allocated at the
// same address.
//
// One per thread that runs streams (the control loop); not thread-safe.
#pragma once

#include <cstddef>
#include <cstdint>
#include <list>
#include <memory>
#include <optional>
#include <span>
#include <unordered_map>
#include <vector>

namespace gmr::server {

class CompiledForm;

class FkBlocks {
 public:
  static constexpr std::size_t kFrames = 16;  // per block

  // budget_bytes: what the kept blocks may take; 0 keeps none, each frame then
  // being computed on its own by the one-frame kernel (FkFrameJob), as before.
  explicit FkBlocks(std::size_t budget_bytes) : budget_(budget_bytes) {}
  FkBlocks(const FkBlocks&) = delete;
  FkBlocks& operator=(const FkBlocks&) = delete;

  struct Pose {
    std::span<const float> positions;     // joints * 3, frame-major as FkFrameJob writes them
    std::span<const float> orientations;  // joints * 9 (row-major W_j); empty unless asked for
  };
  // Frame `frame` of `form`'s compiled motion, valid until the next call;
  // nullopt when the form did not compile or the frame is past its end.
  // `workspace`: at least form.workspace_floats() floats.
  std::optional<Pose> frame(const std::shared_ptr<const CompiledForm>& form, std::size_t frame, bool orientations,
                            std::span<float> workspace);

  std::size_t budget() const { return budget_; }
  std::size_t bytes() const { return bytes_; }                 // taken by the kept blocks
  std::size_t blocks() const { return lru_.size(); }           // kept
  std::uint64_t blocks_computed() const { return computed_; }  // range-kernel runs
  std::uint64_t hits() const { return hits_; }                 // frames read from a kept block
  std::uint64_t frames_alone() const { return alone_; }        // frames computed on their own (budget 0)

 private:
  struct Key {
    const CompiledForm* form = nullptr;
    std::size_t block = 0;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    std::size_t operator()(const Key& k) const noexcept {
      return std::hash<const void*>()(k.form) ^ (k.block * 0x9E3779B97F4A7C15ULL);
    }
  };
  struct Block {
    Key key;
    std::weak_ptr<const CompiledForm> owner;
    bool orientations = false;
    std::vector<float> positions, rotations;  // kFrames frames, fewer for a motion's last block
    std::size_t bytes() const { return (positions.size() + rotations.size()) * sizeof(float); }
  };
  using List = std::list<Block>;

  // A block for `key` at the front of the LRU list, evicting what the budget
  // needs; its vectors are an evicted block's when one was.
  List::iterator make_room(const Key& key, std::size_t bytes_needed);

  std::size_t budget_;
  std::size_t bytes_ = 0;
  List lru_;  // most recently used first
  std::unordered_map<Key, List::iterator, KeyHash> index_;
  std::vector<float> alone_positions_, alone_rotations_;  // budget 0
  std::uint64_t computed_ = 0, hits_ = 0, alone_ = 0;
};

}  // namespace gmr::server
