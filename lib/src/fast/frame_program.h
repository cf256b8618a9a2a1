// Private to the fast path: what CompiledMotion::compile precomputes per
// joint (JointPlan) and the one-frame kernel's program (FrameProgram). The
// layout may change; nothing outside lib/src/fast (and its tests) sees it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "gmr/fast/compiled_motion.h"

namespace gmr::fast {

// No stream: the value is static.
inline constexpr std::int32_t kNoStream = -1;
// World-rotation slot of a joint whose world rotation is the identity.
inline constexpr std::int32_t kIdentitySlot = -1;

// What forward kinematics needs to know about one joint.
struct JointPlan {
  std::int32_t parent = kNoParent;
  std::int32_t rotation_count = 0;   // 0..3 rotation channels computed (0: none, always identity, or a twin's)
  std::uint8_t axes[3] = {0, 0, 0};  // Axis of each rotation channel, listed order
  std::int32_t rotation_stream[3] = {kNoStream, kNoStream, kNoStream};
  std::int32_t offset_stream[3] = {kNoStream, kNoStream, kNoStream};  // per axis: stream or static
  float offset[3] = {0, 0, 0};                                        // static offset components (used where no stream)
  std::int32_t world_slot = kIdentitySlot;   // where W_j lives (shared with the parent without rotation)
  std::int32_t parent_slot = kIdentitySlot;  // where W_p lives (roots: identity)
  bool owns_slot = false;                    // W_j is computed into world_slot (it has rotation channels)
  bool world_for_positions = false;          // W_j must be computed even when no orientation is asked
  bool zero_offset = false;                  // t_j is statically zero
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
    std::uint8_t count = 0;  // rotation channels: 1..3
    std::uint8_t axes[3] = {0, 0, 0};
    std::uint32_t first = 0;  // first local index (multiple of kFrameAlignment)
    std::uint32_t size = 0;   // local indices, padded to kFrameAlignment
  };
  struct Step {
    std::int32_t from = 0;        // float offset of W_s in the world buffer ((slot + 1) * 12; identity: 0)
    std::int32_t out = 0;         // float offset W_s R_j is stored to
    std::int32_t local = 0;       // local index of R_j
    std::int32_t parent = 0;      // float offset of P_p in the position buffer ((parent + 1) * 4; roots: 0)
    std::int32_t pos = 0;         // float offset P_j is stored to ((j + 1) * 4; roots: a scratch entry)
    std::int32_t t = 0;           // float offset of t_j in the offsets buffer (j * 4)
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
  std::vector<std::int32_t> gather;  // 3 * local_count stream offsets (stream * frame_stride)
  // The same angles stored frame-major at compile time: frame f's 3 *
  // local_count angles (gather order, padding included) start at
  // angles.get() + f * 3 * local_count, 64-byte aligned, so the kernel reads
  // them with contiguous vector loads instead of the gather.
  struct AngleFree {
    void operator()(float* p) const;
  };
  std::unique_ptr<float[], AngleFree> angles;
  std::vector<Group> groups;
  std::vector<Step> steps;  // one per joint with rotation channels of its own
  std::vector<PosOp> ops;   // position-only ops: the first `prologue` before the steps, the rest after theirs
  std::uint32_t prologue = 0;
  std::vector<PosOp> leaves;         // non-root joints without rotation channels or children (empty if all roots)
  std::vector<std::int32_t> roots;   // root joints: P_j = t_j, written before the steps
  std::vector<float> offsets;        // joints * 4: static t_j (stream components: 0, patched per frame)
  std::vector<Patch> patches;        // offset components that come from position channels
  std::size_t workspace_floats = 0;  // scratch the kernel needs (64-byte aligned start)
};

namespace detail {

struct CompiledPlan {
  std::vector<JointPlan> joints;
  FrameProgram program;
};

struct PlanAccess {
  static const CompiledPlan& plan(const CompiledMotion& m) { return *m.plan_; }
  static CompiledPlan& plan(CompiledMotion& m) { return *m.plan_; }
};

}  // namespace detail

// The per-joint plans of a compiled motion, in joint order.
inline std::span<const JointPlan> joint_plans(const CompiledMotion& m) { return detail::PlanAccess::plan(m).joints; }
// The one-frame kernel's program.
inline const FrameProgram& frame_program(const CompiledMotion& m) { return detail::PlanAccess::plan(m).program; }

}  // namespace gmr::fast
