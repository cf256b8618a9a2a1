// A counter of the rotation work done by the reference forward kinematics, so
// tests can check that a configuration computes positions without rotation
// math (the fully translational one: every joint a root) instead of timing it.
#pragma once

#include <cstdint>

namespace gmr {

// Number of joint rotations (local rotation composed from channels and
// multiplied into a world orientation) that compute_frame / compute_positions
// evaluated on the calling thread since the last reset. Per thread, so other
// threads never disturb a test.
std::uint64_t fk_rotation_evaluations();
void reset_fk_rotation_evaluations();

}  // namespace gmr
