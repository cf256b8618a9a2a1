// A compiled, read-only float form of a motion for fast forward kinematics.
//
// Layout (structure of arrays across frames):
//
//   stream s:  [ f0 f1 f2 ... f(n-1) | 0 0 ... 0 ]   frame_stride() floats, 64-byte aligned
//               one stream per rotation channel (degrees, reduced to [-180, 180])
//               and per position channel (file units)
//
// so forward kinematics runs across frames in SIMD lanes: one vector holds the
// same channel of 4, 8 or 16 consecutive frames. Streams are padded with zeros
// to a multiple of kFrameAlignment plus one extra block, so a vector load that
// starts at any frame < frame_count() stays inside the stream.
//
// Siblings whose rotation channels are identical in every frame (what a BVH ->
// GMR conversion makes: each child carries a copy of its parent's rotation)
// share one world rotation, computed once; the copies get no streams.
//
// Per joint the compiler precomputes what the convention needs (the parent,
// the rotation axes in listed order, which offset components come from
// position channels, the static offset, and where the joint's world rotation
// lives), and a program for the one-frame kernel. Both are private to the
// fast path (lib/src/fast/frame_program.h): their layout may change.
//
// When every joint is a root (the all-roots GMR form) the positions are the
// joints' effective offsets: they are also stored frame-major, exactly as the
// FK jobs write them, and stored_positions(f) is a zero-copy view of them.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr::fast {

// Frames per padded block: 16 floats = one AVX-512 register (smaller vectors
// divide it).
inline constexpr std::size_t kFrameAlignment = 16;

namespace detail {
struct CompiledPlan;  // the per-joint plans and the one-frame program (lib/src/fast/frame_program.h)
struct PlanAccess;
}  // namespace detail

class CompiledMotion {
 public:
  CompiledMotion();
  ~CompiledMotion();
  CompiledMotion(CompiledMotion&&) noexcept;
  CompiledMotion& operator=(CompiledMotion&&) noexcept;
  CompiledMotion(const CompiledMotion&) = delete;
  CompiledMotion& operator=(const CompiledMotion&) = delete;

  // Compiles `motion` (either convention). Fails when motion.validate() fails
  // or the motion is too large to index with 32-bit stream offsets.
  static Result<CompiledMotion> compile(const Motion& motion);

  Convention convention() const { return convention_; }
  std::size_t frame_count() const { return frame_count_; }
  std::size_t joint_count() const { return joint_count_; }
  std::size_t stream_count() const { return stream_count_; }
  // Floats per stream (frame_count rounded up to kFrameAlignment, plus one block).
  std::size_t frame_stride() const { return frame_stride_; }
  // Number of world-rotation slots a frame needs.
  std::size_t slot_count() const { return slot_count_; }
  // Values of stream s: frame_stride() floats, 64-byte aligned.
  const float* stream(std::size_t s) const { return streams_.get() + s * frame_stride_; }

  // For one-frame FK: stream(s) - stream(0) of every computed rotation
  // channel, in joint order, padded with zeros to a multiple of
  // kFrameAlignment (a frame's angles are one gather).
  std::span<const std::int32_t> rotation_gather_offsets() const { return rotation_offsets_; }

  // True when every joint is a root.
  bool all_roots() const { return all_roots_; }
  // All roots: the positions of `frame` (joint, xyz), identical to what
  // FkRangeJob writes; a zero-copy view. A motion without channels stores
  // one frame for all its frames. Only for all-roots motions.
  const float* stored_positions(std::size_t frame) const;

  // Bytes held per frame (streams and stored positions, padding excluded;
  // not counting the one-frame kernel's frame-major angle copy,
  // frame_program_bytes_per_frame()).
  std::size_t bytes_per_frame() const;
  // Bytes per frame of the FrameProgram's frame-major angle copy
  // (3 * local_count floats, padding included).
  std::size_t frame_program_bytes_per_frame() const;
  // Bytes held in total (padding included).
  std::size_t bytes() const;

 private:
  void build_frame_program();

  struct AlignedFree {
    void operator()(float* p) const;
  };

  Convention convention_ = Convention::kPreRotation;
  std::size_t frame_count_ = 0;
  std::size_t stream_count_ = 0;
  std::size_t frame_stride_ = kFrameAlignment;
  std::size_t slot_count_ = 0;
  bool all_roots_ = false;
  std::size_t joint_count_ = 0;
  std::unique_ptr<float[], AlignedFree> streams_;
  std::vector<float> stored_positions_;
  bool positions_per_frame_ = true;  // false: stored_positions_ holds one frame for all
  std::vector<std::int32_t> rotation_offsets_;
  std::unique_ptr<detail::CompiledPlan> plan_;

  friend struct detail::PlanAccess;
};

}  // namespace gmr::fast
