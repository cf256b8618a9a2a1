// What the retarget and the contact pinning both ask of a rig's joints.
#pragma once

#include "gmr/core/rotation.h"
#include "gmr/skeleton/skeleton.h"

namespace gmr::detail {

// Whether `ancestor` is above `j` in its tree.
inline bool below(const Skeleton& s, int ancestor, int j) {
  for (int k = s.joint(j).parent; k != kNoParent; k = s.joint(k).parent) {
    if (k == ancestor) return true;
  }
  return false;
}

// The joint's first three rotation channels in order and their value slots;
// false when it has fewer than three.
inline bool rotation_slots(const Skeleton& s, int j, Axis order[3], int slots[3]) {
  const Joint& joint = s.joint(j);
  int found = 0;
  for (std::size_t c = 0; c < joint.channels.size() && found < 3; ++c) {
    if (is_rotation(joint.channels[c])) {
      order[found] = axis_of(joint.channels[c]);
      slots[found++] = s.channel_offset(j) + static_cast<int>(c);
    }
  }
  return found == 3;
}

}  // namespace gmr::detail
