// The built-in demo library: a few procedural motions on a human skeleton, so
// the server and the tools work out of the box without any capture file.
//
//                      head_top
//                         |
//                       head
//                         |
//   l_hand - l_wrist - l_elbow - l_shoulder   neck   r_shoulder - ...
//                                      \       |      /
//                                           chest           (three children)
//                                             |
//                                           spine
//                                             |
//                       l_hip ------------ pelvis ------------ r_hip   (root, three children)
//                         |                                      |
//                       l_knee - l_ankle - l_toe               (mirror)
//
// The motions are pre-rotation (GMR): a joint's rotation turns the bone that
// ends at it, so every child of pelvis and chest moves independently, with no
// dummy joints. Units are centimetres, Y is up, the figure faces +Z.
#pragma once

#include <string>
#include <vector>

#include "gmr/motion/motion.h"

namespace gmr {

struct NamedMotion {
  std::string name;  // file-name friendly: "walk", "wave", ...
  Motion motion;
};

// The human skeleton every demo motion uses (pre-rotation; root channels
// X/Y/Zposition Z/X/Yrotation, every other joint Z/X/Yrotation).
Skeleton demo_skeleton();

// The demo motions, generated the same way on every call (deterministic).
std::vector<NamedMotion> demo_library();

}  // namespace gmr
