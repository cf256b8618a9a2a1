// The range kernel's output step: one block of frames from the kernel's
// scratch into the caller's position and orientation arrays, in either layout.
#include <cstring>

#include "fast/fk_kernels.h"

namespace gmr::fast::detail {
namespace {

constexpr float kIdentity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};

}  // namespace

void write_block(const RangeArgs& a, std::size_t f0, std::size_t count, std::size_t lanes, const float* world,
                 const float* pos, bool positions_written) {
  const CompiledMotion& m = *a.motion;
  const std::size_t joints = m.joint_count();
  const std::size_t first = f0 - a.begin;
  if (a.positions && !positions_written) {
    const std::size_t comps = joints * 3;
    if (a.layout == Layout::kFrameMajor) {
      for (std::size_t l = 0; l < count; ++l) {
        float* dst = a.positions_out + (first + l) * comps;
        for (std::size_t k = 0; k < comps; ++k) dst[k] = pos[k * lanes + l];
      }
    } else {
      for (std::size_t k = 0; k < comps; ++k)
        std::memcpy(a.positions_out + k * a.stride + first, pos + k * lanes, count * sizeof(float));
    }
  }
  if (a.orientations == nullptr) return;
  const auto plans = joint_plans(m);
  for (std::size_t j = 0; j < joints; ++j) {
    const std::int32_t slot = plans[j].world_slot;
    const float* w = slot == kIdentitySlot ? nullptr : world + static_cast<std::size_t>(slot) * 9 * lanes;
    for (std::size_t e = 0; e < 9; ++e) {
      if (a.layout == Layout::kFrameMajor) {
        for (std::size_t l = 0; l < count; ++l) {
          a.orientations[((first + l) * joints + j) * 9 + e] = w == nullptr ? kIdentity[e] : w[e * lanes + l];
        }
      } else {
        float* dst = a.orientations + (j * 9 + e) * a.stride + first;
        for (std::size_t l = 0; l < count; ++l) dst[l] = w == nullptr ? kIdentity[e] : w[e * lanes + l];
      }
    }
  }
}

}  // namespace gmr::fast::detail
