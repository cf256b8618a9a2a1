// The positions CSV contract shared by `gmr positions`, `gmr query` and tests:
//
//   frame,joint,x,y,z
//   0,Hips,1.5,90.25,-3
//
// One row per frame and joint (End Sites included), joints in skeleton order,
// frames numbered as given, numbers in shortest round-tripping form.
#pragma once

#include <Eigen/Core>
#include <ostream>
#include <span>
#include <string>
#include <string_view>

#include "gmr/skeleton/skeleton.h"

namespace gmr {

void write_positions_csv_header(std::ostream& out);
// A name as one CSV field: RFC 4180 quoting, only when it needs it (a ',',
// '"' or line break); the joint column here and `gmr markers` use it.
std::string csv_field(std::string_view name);
// Rows for `positions` (frame-major, skeleton.size() per frame); the first
// frame is numbered `first_frame`.
void write_positions_csv_rows(std::ostream& out, const Skeleton& skeleton, std::span<const Eigen::Vector3d> positions,
                              std::size_t first_frame);

}  // namespace gmr
