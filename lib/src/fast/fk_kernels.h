// Private interface between the FK jobs (fast_fk.cpp) and the per-target SIMD
// kernels (fk_kernels.cpp).
#pragma once

#include <cstddef>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "fast/frame_program.h"

namespace gmr::fast::detail {

struct RangeArgs {
  const CompiledMotion* motion = nullptr;
  std::size_t begin = 0;
  std::size_t end = 0;
  Layout layout = Layout::kFrameMajor;
  std::size_t stride = 0;          // kJointMajor: floats between components
  float* positions_out = nullptr;  // written when `positions`
  float* orientations = nullptr;   // null: none
  float* workspace = nullptr;      // 64-byte aligned
  bool positions = true;           // false: positions are copied elsewhere (all roots)
};

struct FrameArgs {
  const CompiledMotion* motion = nullptr;
  std::size_t frame = 0;
  float* positions = nullptr;     // joints * 3 (all roots: left to the caller)
  float* orientations = nullptr;  // null or joints * 9
  float* workspace = nullptr;     // 64-byte aligned, frame_workspace_floats()
  std::size_t padded_angles = 0;  // rotation channels rounded up to kFrameAlignment
};

// One frame by the motion's FrameProgram (4-float column vectors); false when
// the CPU's best target has no 128-bit vectors (then the caller runs its
// scalar chain).
bool frame_kernel(const FrameArgs& args);

// Runs the best kernel for this CPU over [begin, end).
void range_kernel(const RangeArgs& args);
// Writes `count` frames starting at f0 from the block scratch (world: slot
// major, pos: joint major, `lanes` floats per component) to the outputs.
// positions_written: the kernel already stored this block's positions.
void write_block(const RangeArgs& args, std::size_t f0, std::size_t count, std::size_t lanes, const float* world,
                 const float* pos, bool positions_written);
// sin and cos of angles in degrees; count rounded up to kFrameAlignment must
// fit all three buffers.
void sincos_degrees(const float* angles, std::size_t count, float* out_s, float* out_c);
const char* target_name();
std::size_t lane_count();

}  // namespace gmr::fast::detail
