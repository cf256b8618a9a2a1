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
#include <filesystem>
#include <optional>
#include <ostream>
#include <span>
#include <string>
#include <string_view>

#include "gmr/core/error.h"
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
// `--local-transforms`: each row also holds the joint's engine-bone local
// transform (gmr/view/engine_pose.h) in the rows' conventions, after any
// orientation columns: lqw,lqx,lqy,lqz (lqw >= 0) and ltx,lty,ltz, the
// rotation and translation relative to the parent joint's frame (a root's:
// to the output frame).
struct PoseColumns {
  std::optional<OrientationColumns> orientations;  // none: no orientation columns
  bool local_transforms = false;
};
// One chunk of rows, frame-major, skeleton.size() per frame; the spans a
// column set does not ask for may be empty.
struct PoseRows {
  std::span<const Eigen::Vector3d> positions;
  std::span<const Eigen::Matrix3d> orientations;
  std::span<const Eigen::Quaterniond> local_rotations;
  std::span<const Eigen::Vector3d> local_translations;
};
void write_pose_header(std::ostream& out, const PoseColumns& columns);
void write_pose_rows(std::ostream& out, const Skeleton& skeleton, const PoseRows& rows, std::size_t first_frame,
                     const PoseColumns& columns);

// A name as one CSV field: RFC 4180 quoting, only when it needs it (a ',',
// '"' or line break); the joint column here and `gmr markers` use it.
std::string csv_field(std::string_view name);
// Rows for `positions` (frame-major, skeleton.size() per frame); the first
// frame is numbered `first_frame`.
void write_positions_csv_rows(std::ostream& out, const Skeleton& skeleton, std::span<const Eigen::Vector3d> positions,
                              std::size_t first_frame);

// What a positions CSV (or a poses CSV, with quaternion or matrix columns)
// holds, read back: `gmr publish x.csv` plays it as an all-roots source.
struct PositionsTable {
  std::vector<std::string> joints;  // the first frame's rows, in order
  std::size_t first_frame = 0;      // the first row's frame number
  std::size_t frames = 0;
  std::vector<Eigen::Vector3d> positions;        // frame-major, joints.size() per frame
  std::vector<Eigen::Quaterniond> orientations;  // the same, when the file has orientation columns; else empty
};
// Parses one of the three headers above and its rows. Every frame has the
// first frame's joints in the same order, frames are numbered one after the
// other, numbers are finite and orientations are rotations; anything else is
// an error naming `source`, the line and the column.
Result<PositionsTable> parse_positions_csv(std::string_view text, const std::string& source);
Result<PositionsTable> read_positions_csv(const std::filesystem::path& path);

}  // namespace gmr
