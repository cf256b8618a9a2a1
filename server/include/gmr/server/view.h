// A view: one connection's own copy of a motion's root configuration, edited
// by shift/split/join/set-roots/strip-dummies, seen in world coordinates or
// from a joint (the intrinsic viewpoint).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr::server {

// What a frame of a view is computed from; immutable once built, shared by
// the streams that send it.
struct ViewContent {
  std::shared_ptr<const Motion> motion;  // pre-rotation
  int relative_to = -1;                  // joint index of the viewer; -1: world
  std::uint32_t skeleton_version = 1;
};

// Positions (and orientations, when out_orientations is not empty) of every
// joint of frame f, in the view's coordinates:
//   world:     P_j, W_j from forward kinematics
//   intrinsic: W_v^T (P_j - P_v), W_v^T W_j for viewer v
// The one place the server computes kinematics: swap the FK here.
void compute_view_frame(const ViewContent& view, std::size_t f, std::span<Eigen::Vector3d> out_positions,
                        std::span<Eigen::Matrix3d> out_orientations);

class View {
 public:
  View(std::uint32_t id, std::string motion_name, std::shared_ptr<const Motion> motion);

  std::uint32_t id() const { return id_; }
  const std::string& motion_name() const { return motion_name_; }
  const std::shared_ptr<const ViewContent>& content() const { return content_; }
  const Motion& motion() const { return *content_->motion; }

  // Each edit either applies and bumps skeleton_version, or fails and leaves
  // the view as it was. Joints by name; errors name the joint and the reason.
  Status shift_root(const std::string& joint);
  Status split(const std::string& joint);
  Status join(const std::string& root, double* out_offset_spread = nullptr);
  Status set_roots(const std::vector<std::string>& roots);
  Status strip_dummies(std::vector<std::string>* out_removed = nullptr);
  Status set_relative_to(const std::string& joint);  // empty: world coordinates

  // The joint's index, or an error "view 3 (walk) has no joint 'x'".
  Result<int> joint_index(const std::string& name) const;

 private:
  void replace(std::shared_ptr<const Motion> motion, int relative_to);

  std::uint32_t id_;
  std::string motion_name_;
  std::shared_ptr<const ViewContent> content_;
};

}  // namespace gmr::server
