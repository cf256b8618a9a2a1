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
// Per joint the compiler precomputes what the convention needs (JointPlan):
// the parent, the rotation axes in listed order, which offset components come
// from position channels, the static offset, and where the joint's world
// rotation lives (its own slot, its parent's when it has no rotation, or the
// identity).
//
// When every joint is a root (the all-roots GMR form) the positions are the
// joints' effective offsets: they are also stored frame-major, exactly as the
// FK jobs write them, and stored_positions() is a zero-copy view of them.
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

// No stream: the value is static.
inline constexpr std::int32_t kNoStream = -1;
// World-rotation slot of a joint whose world rotation is the identity.
inline constexpr std::int32_t kIdentitySlot = -1;

// What forward kinematics needs to know about one joint.
struct JointPlan {
  std::int32_t parent = kNoParent;
  std::int32_t rotation_count = 0;               // 0..3 rotation channels computed (0: none, always identity, or a twin's)
  std::uint8_t axes[3] = {0, 0, 0};              // Axis of each rotation channel, listed order
  std::int32_t rotation_stream[3] = {kNoStream, kNoStream, kNoStream};
  std::int32_t offset_stream[3] = {kNoStream, kNoStream, kNoStream};  // per axis: stream or static
  float offset[3] = {0, 0, 0};                   // static offset components (used where no stream)
  std::int32_t world_slot = kIdentitySlot;       // where W_j lives (shared with the parent without rotation)
  std::int32_t parent_slot = kIdentitySlot;      // where W_p lives (roots: identity)
  bool owns_slot = false;                        // W_j is computed into world_slot (it has rotation channels)
  bool world_for_positions = false;              // W_j must be computed even when no orientation is asked
  bool zero_offset = false;                      // t_j is statically zero
};

// The one-frame kernel's program, built once by compile() so that FkFrameJob
// runs flat, branch-free loops (internal to the fast path; the layout may change).
//
// Rotating joints are numbered by "local index" (grouped by axis order, each
// group padded to kFrameAlignment; local_count in all). Per frame the kernel
//   1. copies angle r of every local index into a contiguous role-major
//      array (from gather[r * local_count + i] = stream offset relative to
//      stream 0; padding reads stream 0), and runs one SIMD sincos over the
//      3 * local_count angles;
//   2. per group, computes the local rotations R_j with straight-line code for
//      the group's axis order, SIMD across joints (entry 3 row + col of local
//      index i at local[(3 row + col) * local_count + i]);
//   3. per step (one per joint with its own rotation, in joint order),
//      W_j = W_s R_j and P_j = P_p + W t_j, with W = W_j (pre-rotation) or
//      W_s (post), all in registers, then the step's position-only ops (below).
//      Slot 0 of the world buffer is the identity (the roots' W_s); roots'
//      positions (P_j = t_j) are written before the steps and a rotating
//      root's step stores P_j to a scratch entry.
//   4. position-only ops P_j = P_p + W t_j, W read back from the world
//      buffer, for joints without rotation channels of their own: a twin (it
//      shares its sibling's W), or a joint that takes its parent's W. Ops
//      whose inputs are ready before any step run first (the first
//      `prologue` ops); the others follow the step that makes their inputs
//      ready, so the program keeps joint order. Leaves without rotation
//      channels (end sites) run last. Roots without rotation channels need
//      nothing (W = identity, P = t).
struct FrameProgram {
  struct Group {
    std::uint8_t count = 0;        // rotation channels: 1..3
    std::uint8_t axes[3] = {0, 0, 0};
    std::uint32_t first = 0;       // first local index (multiple of kFrameAlignment)
    std::uint32_t size = 0;        // local indices, padded to kFrameAlignment
  };
  struct Step {
    std::int32_t from = 0;       // float offset of W_s in the world buffer ((slot + 1) * 12; identity: 0)
    std::int32_t out = 0;        // float offset W_s R_j is stored to
    std::int32_t local = 0;      // local index of R_j
    std::int32_t parent = 0;     // float offset of P_p in the position buffer ((parent + 1) * 4; roots: 0)
    std::int32_t pos = 0;        // float offset P_j is stored to ((j + 1) * 4; roots: a scratch entry)
    std::int32_t t = 0;          // float offset of t_j in the offsets buffer (j * 4)
    std::uint32_t ops_begin = 0;  // position-only ops run after this step: ops[ops_begin, ops_end)
    std::uint32_t ops_end = 0;
  };
  // P_j = P_p + W t_j with W (already computed) read back from the world buffer.
  struct PosOp {
    std::int32_t world = 0;   // float offset of W
    std::int32_t parent = 0;  // float offset of P_p
    std::int32_t pos = 0;     // float offset P_j is stored to ((j + 1) * 4)
    std::int32_t t = 0;       // float offset of t_j (j * 4)
  };
  struct Patch {
    std::int32_t dst = 0;     // float index in the offsets buffer (joint * 4 + axis)
    std::int32_t stream = 0;  // stream supplying it
  };
  std::size_t local_count = 0;
  std::vector<std::int32_t> gather;    // 3 * local_count stream offsets (stream * frame_stride)
  // The same angles stored frame-major at compile time: frame f's 3 *
  // local_count angles (gather order, padding included) start at
  // angles.get() + f * 3 * local_count, 64-byte aligned, so the kernel reads
  // them with contiguous vector loads instead of the gather.
  struct AngleFree {
    void operator()(float* p) const;
  };
  std::unique_ptr<float[], AngleFree> angles;
  std::vector<Group> groups;
  std::vector<Step> steps;             // one per joint with rotation channels of its own
  std::vector<PosOp> ops;              // position-only ops: the first `prologue` before the steps, the rest after theirs
  std::uint32_t prologue = 0;
  std::vector<PosOp> leaves;           // non-root joints without rotation channels or children (empty if all roots)
  std::vector<std::int32_t> roots;     // root joints: P_j = t_j, written before the steps
  std::vector<float> offsets;          // joints * 4: static t_j (stream components: 0, patched per frame)
  std::vector<Patch> patches;          // offset components that come from position channels
  std::size_t workspace_floats = 0;    // scratch the kernel needs (64-byte aligned start)
};

class CompiledMotion {
 public:
  CompiledMotion() = default;
  CompiledMotion(CompiledMotion&&) noexcept = default;
  CompiledMotion& operator=(CompiledMotion&&) noexcept = default;
  CompiledMotion(const CompiledMotion&) = delete;
  CompiledMotion& operator=(const CompiledMotion&) = delete;

  // Compiles `motion` (either convention). Fails when motion.validate() fails
  // or the motion is too large to index with 32-bit stream offsets.
  static Result<CompiledMotion> compile(const Motion& motion);

  Convention convention() const { return convention_; }
  std::size_t frame_count() const { return frame_count_; }
  std::size_t joint_count() const { return plans_.size(); }
  std::size_t stream_count() const { return stream_count_; }
  // Floats per stream (frame_count rounded up to kFrameAlignment, plus one block).
  std::size_t frame_stride() const { return frame_stride_; }
  // Number of world-rotation slots a frame needs.
  std::size_t slot_count() const { return slot_count_; }
  std::span<const JointPlan> joints() const { return plans_; }
  // Values of stream s: frame_stride() floats, 64-byte aligned.
  const float* stream(std::size_t s) const { return streams_.get() + s * frame_stride_; }

  // For one-frame FK: stream(s) - stream(0) of every computed rotation
  // channel, in joint order, padded with zeros to a multiple of
  // kFrameAlignment (a frame's angles are one gather).
  std::span<const std::int32_t> rotation_gather_offsets() const { return rotation_offsets_; }

  // The one-frame kernel's program (see FrameProgram).
  const FrameProgram& frame_program() const { return program_; }

  // True when every joint is a root.
  bool all_roots() const { return all_roots_; }
  // All roots: the positions of every frame, frame-major (frame, joint, xyz),
  // identical to what FkRangeJob writes. Empty otherwise.
  std::span<const float> stored_positions() const { return stored_positions_; }

  // Bytes held per frame (streams and stored positions, padding excluded;
  // not counting the one-frame kernel's frame-major angle copy,
  // frame_program_bytes_per_frame()).
  std::size_t bytes_per_frame() const;
  // Bytes per frame of the FrameProgram's frame-major angle copy
  // (3 * local_count floats, padding included).
  std::size_t frame_program_bytes_per_frame() const { return 3 * program_.local_count * sizeof(float); }
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
  std::vector<JointPlan> plans_;
  std::unique_ptr<float[], AlignedFree> streams_;
  std::vector<float> stored_positions_;
  std::vector<std::int32_t> rotation_offsets_;
  FrameProgram program_;
};

}  // namespace gmr::fast
