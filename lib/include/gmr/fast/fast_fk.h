// Fast forward kinematics on a CompiledMotion, in float.
//
// Jobs in the ozz style: fill the public fields, call run(). Inputs are a
// const CompiledMotion and a frame range, outputs are caller-owned spans, and
// run() allocates nothing: it needs a caller-owned `workspace` of at least
// fk_workspace_size(motion) floats (one per thread; reuse it across calls).
//
// Results match the double reference path (gmr/kinematics/forward_kinematics.h)
// to float round-off: positions within about 1e-6 of the skeleton's size.
// The SIMD width is picked at run time (SSE4, AVX2 or AVX-512 on x86-64).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "gmr/core/error.h"
#include "gmr/fast/compiled_motion.h"

namespace gmr::fast {

// How FkRangeJob lays out what it writes.
enum class Layout : std::uint8_t {
  // Frame-major, as compute_positions(): positions[((f - begin) * joints + j) * 3 + axis],
  // orientations[((f - begin) * joints + j) * 9 + 3 * row + col].
  kFrameMajor,
  // Joint-major, frames contiguous (structure of arrays):
  // positions[(j * 3 + axis) * stride + (f - begin)], orientations[(j * 9 + 3 * row + col) * stride + (f - begin)],
  // stride = joint_major_stride (or end - begin when 0).
  kJointMajor,
};

// Floats of workspace the jobs need for `motion`.
std::size_t fk_workspace_size(const CompiledMotion& motion);

// World positions (and optionally orientations W_j, row-major 3x3) of every
// joint for frames [begin, end).
struct FkRangeJob {
  const CompiledMotion* motion = nullptr;
  std::size_t begin = 0;
  std::size_t end = 0;  // exclusive; begin <= end <= frame_count
  Layout layout = Layout::kFrameMajor;
  std::size_t joint_major_stride = 0;  // kJointMajor only: floats between components; 0 = end - begin
  std::span<float> out_positions;      // (end - begin) * joints * 3 floats (kJointMajor: joints * 3 * stride)
  std::span<float> out_orientations;   // empty, or (end - begin) * joints * 9 (kJointMajor: joints * 9 * stride)
  std::span<float> workspace;          // >= fk_workspace_size(*motion)

  // Names the first broken rule: no motion, range out of bounds, an output or
  // the workspace too small, a stride smaller than the range.
  Status check() const;
  bool validate() const { return check().ok(); }
  // validate(), then computes. Returns false (writing nothing) when invalid.
  bool run() const;
};

// One frame (what a server does per tick): frame-major positions (joints * 3)
// and optionally orientations (joints * 9).
struct FkFrameJob {
  const CompiledMotion* motion = nullptr;
  std::size_t frame = 0;  // < frame_count
  std::span<float> out_positions;
  std::span<float> out_orientations;  // empty or joints * 9
  std::span<float> workspace;         // >= fk_workspace_size(*motion)

  Status check() const;
  bool validate() const { return check().ok(); }
  bool run() const;
};

// Baseline for benchmarks: the same frame computed one joint at a time with
// std::sin/std::cos in float, no SIMD (the "scalar float" path). Same contract
// as FkFrameJob (positions only); returns false when the arguments are invalid.
bool scalar_float_frame(const CompiledMotion& motion, std::size_t frame, std::span<float> out_positions,
                        std::span<float> workspace);

// Name of the SIMD target the dispatcher picked on this CPU (e.g. "AVX3", "AVX2").
const char* simd_target_name();
// Float lanes per vector on that target (4, 8 or 16).
std::size_t simd_lanes();

}  // namespace gmr::fast
