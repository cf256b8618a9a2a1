// The GMR operations on a whole motion (every frame), paper section 4.1 with
// the primes restored in ../shared/GMR-MATH.md. Every operation keeps every
// joint's world position in every frame. They take and return pre-rotation
// motions (a post-rotation one is an error: convert it with to_pre_rotation).
// Joints are named by index; joint names never change.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// Every operation fails (without touching its input) for a post-rotation
// motion, an invalid one (Motion::validate), or a joint index out of range.
// Results keep parents before children: joints may be reordered (stable: the
// lowest index among the joints that can come next), names never change.
// Computed rotations are stored as Euler channels (decompose_euler, continuous
// over frames) in the joint's own order when it has three rotation channels;
// a joint with fewer gets the missing axes appended when the result needs them.
// Plain copies (e.g. a shift's R1' = R0) copy channel types and values exactly.

// Moves the root of the tree holding `joint` to `joint`, by repeated swaps of a
// root with one of its children along the path. Static offsets stay static
// (the old root gets the negated offset of the joint it now hangs under); the
// new root gets Xposition Yposition Zposition channels. A soft link of the old
// root moves to the new one. No-op when `joint` is already a root.
Result<Motion> shift_root(const Motion& motion, int joint);

// Promotes `joint` to a root with a soft link to its parent: its world
// orientation becomes its rotation channels and its world position its
// Xposition Yposition Zposition channels; its subtree is unchanged.
// Fails when `joint` is already a root.
Result<Motion> split_tree(const Motion& motion, int joint);

// What a join found about the offset it recovered.
struct JoinReport {
  double offset_spread = 0.0;      // largest distance of a frame's recovered offset from their mean
  bool translation_channels = false;  // true when the offset varied and became per-frame channels
};
// Demotes root `root` back under its soft-link parent P: per frame
// R = W_P^-1 W_root, t = W_root^-1 (P_root - P_P). When t is constant (spread
// at most 1e-9 x skeleton_size) it becomes the static offset (its mean);
// otherwise it becomes Xposition Yposition Zposition channels and
// translation_channels is set. Fails for a joint that is not a root, the last
// root of the skeleton, a root with no soft link, or one whose soft link
// points into its own tree.
Result<Motion> join_tree(const Motion& motion, int root, JoinReport* out_report = nullptr);

// Moves from the current roots to exactly the roots `roots`: joins every
// soft-linked root back, keeps the root of each tree when it is in the set and
// otherwise moves it (shift) to the joint of the set nearest to it (ties:
// smallest name), then splits at every other joint of the set. World
// positions never depend on the path. Local data depend only on the connected
// skeleton, its tree roots after the joins, and the set: any configuration
// reached from a motion by set_roots with sets that contain its roots (or by
// splits and joins) gives the same result as set_roots on the motion itself,
// and set_roots back to the original roots restores the original local data.
// Fails for an empty set, a joint listed twice, a connected skeleton (hard
// edges and soft links) with no joint in the set, or soft links that form a
// cycle.
Result<Motion> set_roots(const Motion& motion, std::span<const int> roots);

// A zero-length joint that was removed.
struct RemovedJoint {
  std::string name;
  std::string parent;  // its parent's name
};
// Removes every joint d with an offset of exactly zero and no position
// channels that has a parent and children (CMU's LHipJoint, RHipJoint, ...):
// each child c takes R_d * R_c and d's parent. Roots and leaves are kept; a
// soft link to d moves to d's parent. Reports removed joints in index order.
Result<Motion> strip_dummies(const Motion& motion, std::vector<RemovedJoint>* out_removed = nullptr);

// The converse report: joints that have rotation channels whose local rotation
// is the same in every frame (within `tolerance_degrees` of frame 0), by name
// in index order. Any convention. Empty for a motion with no frames.
std::vector<std::string> constant_rotation_joints(const Motion& motion, double tolerance_degrees = 1e-9);

// The intrinsic viewpoint: positions (and orientations, if requested) of every
// joint in the frame of joint `viewer`, for frames [begin, end) (clamped to the
// motion), frame-major:
//   p' = W_v^T (p - P_v),  W' = W_v^T W
// with P_v, W_v the viewer's world position and orientation as the reference
// forward kinematics reports them (docs/operations.md). Works for both
// conventions. An out-of-range viewer gives empty outputs.
void intrinsic_positions(const Motion& motion, int viewer, std::size_t begin, std::size_t end,
                         std::vector<Eigen::Vector3d>& out_positions,
                         std::vector<Eigen::Matrix3d>* out_orientations = nullptr);

// Indices of the joints named `names`, in the same order; fails on the first
// unknown name ("unknown joint 'X'").
Result<std::vector<int>> find_joints(const Skeleton& skeleton, std::span<const std::string> names);

}  // namespace gmr
