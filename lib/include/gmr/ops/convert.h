// Conversions between the post-rotation (BVH) and pre-rotation (GMR) forms.
// Both keep every joint's world position in every frame.
#pragma once

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// Post-rotation -> pre-rotation (paper 5.2): every root gets R' = I (its
// rotation moves to its children), every other joint j gets its parent's
// rotation R'_j = R_p(j) and keeps its offset and position channels.
// A pre-rotation motion is returned unchanged.
Result<Motion> to_pre_rotation(const Motion& motion);

// Pre-rotation -> post-rotation for a forest of trees. Where a joint's children
// rotate independently, zero-length joints are inserted (the inverse of dummy
// removal) so that the BVH has the same positions. A post-rotation motion is
// returned unchanged.
Result<Motion> to_post_rotation(const Motion& motion);

}  // namespace gmr
