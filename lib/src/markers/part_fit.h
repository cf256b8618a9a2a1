// What marker_solve.cpp (a whole take) and marker_frames.cpp (one frame at a
// time) share: a part's pose, its fit in one frame, a frame's channel values,
// and the calibration a frame solver keeps. Private to lib/src/markers.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <span>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/marker_solve.h"
#include "gmr/skeleton/skeleton.h"

namespace gmr::marker_detail {

// A part's pose in one frame: world = q * local + t.
struct Pose {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& local) const { return q * local + t; }
  Eigen::Vector3d local(const Eigen::Vector3d& world) const { return q.conjugate() * (world - t); }
};

// One frame's fit of a part of 3 or more points: the weighted rigid fit of
// its layout to `points` (NaN: missing) with the outlier rule: while 4 or
// more points remain and the worst residual exceeds `outlier`, the worst
// point that is not a joint (`joint_of` >= 0) is left out and the fit
// redone. False when fewer than 3 usable points remain or they are nearly on
// a line (`min_spread` across the best line). Adds the points left out to
// `outliers` and the residuals of those kept to `sum_sq` and `residuals`.
struct PartFitter {
  std::vector<Eigen::Vector3d> local, world;
  std::vector<double> weights;
  std::vector<std::size_t> which;

  bool fit(const std::vector<Eigen::Vector3d>& layout, const std::vector<double>& point_weights,
           const std::vector<Eigen::Vector3d>& points, const std::vector<int>& joint_of, double outlier,
           double min_spread, Pose& pose, std::size_t& outliers, double& sum_sq, std::size_t& residuals);
};

// A 2-point part (a joint of another part, then a marker) in one frame: the
// other part's pose turned so that the layout's direction meets the marker,
// at the joint. False when the marker is missing or on the joint.
bool fit_two_points(const std::vector<Eigen::Vector3d>& layout, const Pose& other, const Eigen::Vector3d& joint,
                    const Eigen::Vector3d& marker, Pose& pose);

// One frame's channel values of the model's motion from each part's world
// rotation and each joint's world position: roots their position, then
// rotations relative to the parent joint's part, as Z X Y Euler angles (the
// previous frame's, unless `first`, pick the nearest equivalent).
void write_frame(const Skeleton& skeleton, const MarkerModel& model, const std::vector<Eigen::Quaterniond>& part_q,
                 const std::vector<Eigen::Vector3d>& joint_world, std::vector<Eigen::Vector3d>& previous, bool first,
                 std::span<double> values);

// What a frame solver keeps of a calibration, per part.
struct FramePart {
  std::vector<Eigen::Vector3d> layout;
  std::vector<int> marker_of, joint_of;  // per point: marker index, or joint index (-1: the other kind)
  bool fitted_once = false;
  Pose last;  // the last fitted (or held) pose
};

// solve_markers() of `markers` (no roots), keeping each part's layout and
// points and each joint's place in its part.
Result<MarkerSolveResult> solve_keeping(const MarkerTrajectories& markers, const MarkerModel& model,
                                        std::vector<FramePart>& parts, std::vector<Eigen::Vector3d>& joint_local);

}  // namespace gmr::marker_detail
