// The positions CSV contract shared by `gmr positions`, `gmr query` and tests:
//
//   frame,joint,x,y,z
//   0,Hips,1.5,90.25,-3
//
// One row per frame and joint (End Sites included), joints in skeleton order,
// frames numbered as given, numbers in shortest round-tripping form.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <ostream>
#include <span>
#include <string>
#include <string_view>

#include "gmr/skeleton/skeleton.h"

namespace gmr {

void write_positions_csv_header(std::ostream& out);

// `gmr positions --orientations`: each row also holds the joint's world
// orientation W_j, as a unit quaternion (qw,qx,qy,qz with qw >= 0) or as the
// 3x3 matrix row by row (r00,r01,r02,r10,...,r22). Column vectors: W_j maps
// the joint's frame to world axes.
enum class OrientationColumns { kQuaternion, kMatrix };
void write_poses_csv_header(std::ostream& out, OrientationColumns columns);
// Rows of positions and orientations (both frame-major, skeleton.size() per
// frame); with no orientations, the rows of write_positions_csv_rows.
void write_poses_csv_rows(std::ostream& out, const Skeleton& skeleton, std::span<const Eigen::Vector3d> positions,
                          std::span<const Eigen::Matrix3d> orientations, std::size_t first_frame,
                          OrientationColumns columns);
// A name as one CSV field: RFC 4180 quoting, only when it needs it (a ',',
// '"' or line break); the joint column here and `gmr markers` use it.
std::string csv_field(std::string_view name);
// Rows for `positions` (frame-major, skeleton.size() per frame); the first
// frame is numbered `first_frame`.
void write_positions_csv_rows(std::ostream& out, const Skeleton& skeleton, std::span<const Eigen::Vector3d> positions,
                              std::size_t first_frame);

}  // namespace gmr
