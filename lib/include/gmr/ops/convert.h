// Conversions between the post-rotation (BVH) and pre-rotation (GMR) forms.
// Both keep every joint's world position in every frame.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

// Post-rotation -> pre-rotation (paper 5.2): every root gets R' = I (its
// rotation moves to its children), every other joint j gets its parent's
// rotation R'_j = R_p(j) and keeps its offset and position channels.
// A pre-rotation motion is returned unchanged.
Result<Motion> to_pre_rotation(const Motion& motion);

// to_pre_rotation for many motions on one post-rotation skeleton (a live
// view's frames): the conversion only moves channel values (each joint takes
// its parent's rotation channels, a root loses its own), so it is found once,
// by converting a frame whose values are their own slot numbers, and is then a
// gather of values into a skeleton made once.
class PreRotationGather {
 public:
  // Empty when the conversion would compute a value rather than move it.
  static std::optional<PreRotationGather> make(const Skeleton& post);
  const Skeleton& skeleton() const { return skeleton_; }
  // `post`: frames x the post-rotation skeleton's channels, as to_pre_rotation
  // of that motion gives them (its values are not checked: finite in, finite out).
  Motion apply(std::span<const double> post, std::size_t frames, double frame_time) const;

 private:
  Skeleton skeleton_;
  std::size_t post_stride_ = 0;
  std::vector<std::size_t> from_;  // per pre-rotation channel: its post-rotation channel
};

// Pre-rotation -> post-rotation for a forest of trees. Where a joint's children
// rotate independently, zero-length joints named `<child>_gmr_pre` are inserted
// (the inverse of dummy removal) so that the BVH has the same positions: a
// joint whose children fall into k groups of equal rotation gets k - 1 (one
// group rides on the joint itself; the one without rotation when there is
// one). A post-rotation motion is returned unchanged.
Result<Motion> to_post_rotation(const Motion& motion);

struct BvhExportOptions {
  // One ROOT block for readers that take only one tree: a forest's trees hang
  // under a joint named root_name (made unique) at the origin, with no
  // channels; each former root keeps its world position and rotation through
  // six channels. A single tree is left as it is.
  bool single_root = false;
  std::string root_name = "gmr_world";
};

// The motion (either convention) in the post-rotation form that Blender,
// three.js and Assimp read with the same positions as gmr (docs/gmr-format.md,
// "BVH that other programs read"): every joint has 0 or 3 rotation channels
// (missing axes added with zero angles, other layouts re-encoded); position
// channels are none or all three with OFFSET 0, and come with three rotation
// channels (Assimp reads positions only from six-channel joints); a non-root
// joint whose position channels never change gets them as its OFFSET; a
// motion with frames but no channel at all gets six channels on its first
// root (its rows would otherwise be blank lines, which readers skip); soft
// links are dropped. Every joint keeps its name and world position in every frame.
Result<Motion> to_bvh_interchange(const Motion& motion, const BvhExportOptions& options = {});

// World poses sampled per frame (what a subscription delivers) as a GMR
// motion: the fully translational form, every joint a root whose position
// channels hold its world position and whose Zrotation Xrotation Yrotation
// channels its world orientation, so forward kinematics gives back exactly
// the poses (to round-off). `soft_parents[j]` (an index into `names`, or
// kNoParent) becomes joint j's soft link, so `join` and set_roots can
// rebuild the tree; it must come before j. `positions` and (when not empty)
// `orientations` are frame-major, names.size() per frame. Fails on sizes
// that do not match, a soft parent that is not before its joint, a name the
// skeleton refuses, or values that are not finite.
Result<Motion> motion_from_world_poses(const std::vector<std::string>& names, const std::vector<int>& soft_parents,
                                       double frame_time, std::span<const Eigen::Vector3d> positions,
                                       std::span<const Eigen::Quaterniond> orientations);

}  // namespace gmr
