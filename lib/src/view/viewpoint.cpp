#include "gmr/view/viewpoint.h"

#include <Eigen/Geometry>
#include <cassert>
#include <cstring>

#include "gmr/kinematics/forward_kinematics.h"

namespace gmr {

Viewpoint::Viewpoint(const Eigen::Vector3d& origin, const Eigen::Matrix3d& orientation)
    : world_(false), rt_(orientation.transpose()), origin_(origin) {}

Viewpoint Viewpoint::of_joint(std::span<const float> positions, std::span<const float> orientations, std::size_t v) {
  assert(positions.size() >= 3 * (v + 1) && orientations.size() >= 9 * (v + 1));
  const float* p = positions.data() + 3 * v;
  const float* w = orientations.data() + 9 * v;
  Eigen::Matrix3d wv;
  wv << w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7], w[8];
  return Viewpoint(Eigen::Vector3d(p[0], p[1], p[2]), wv);
}

void view_frame(const Motion& motion, int viewer, std::size_t f, std::span<Eigen::Vector3d> out_positions,
                std::span<Eigen::Matrix3d> out_orientations, const OutputBasis& basis) {
  assert(viewer < 0 || out_orientations.size() == out_positions.size());
  compute_frame(motion, f, out_positions, out_orientations);
  if (viewer >= 0) {
    const auto v = static_cast<std::size_t>(viewer);
    const Viewpoint from(out_positions[v], out_orientations[v]);
    for (auto& p : out_positions) p = from.position(p);
    for (auto& w : out_orientations) w = from.orientation(w);
  }
  if (basis.identity) return;
  for (auto& p : out_positions) p = basis.position(p);
  for (auto& w : out_orientations) w = basis.orientation(w);
}

namespace {

// The joints of view_frame_float; without a basis (the native conventions,
// the common case) the loop holds nothing more than the viewpoint: measured,
// applying the basis through run-time tests in this loop cost 20% (and 3x in
// a first form) on native streams (bench: server_frame/bvh).
template <bool kBasis>
void view_joints(std::span<const float> fk_positions, std::span<const float> fk_orientations, const Viewpoint& from,
                 std::span<const int> joints, std::span<float> out_positions, std::span<float> out_quaternions,
                 const OutputBasis& basis) {
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const auto j = static_cast<std::size_t>(joints[i]);
    assert(fk_positions.size() >= 3 * (j + 1));
    const float* p = fk_positions.data() + 3 * j;
    Eigen::Vector3d q = from.position(Eigen::Vector3d(p[0], p[1], p[2]));
    if constexpr (kBasis) q = basis.position(q);
    for (int k = 0; k < 3; ++k) out_positions[3 * i + static_cast<std::size_t>(k)] = static_cast<float>(q[k]);
    if (out_quaternions.empty()) continue;
    assert(fk_orientations.size() >= 9 * (j + 1));
    const float* w = fk_orientations.data() + 9 * j;
    Eigen::Matrix3d m;
    m << w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7], w[8];
    Eigen::Quaterniond r(from.orientation(m));
    if constexpr (kBasis) r = basis.orientation(r);
    float* o = out_quaternions.data() + 4 * i;
    o[0] = static_cast<float>(r.x());
    o[1] = static_cast<float>(r.y());
    o[2] = static_cast<float>(r.z());
    o[3] = static_cast<float>(r.w());
  }
}

}  // namespace

void view_frame_float(std::span<const float> fk_positions, std::span<const float> fk_orientations, int viewer,
                      std::span<const int> joints, std::span<float> out_positions, std::span<float> out_quaternions,
                      const OutputBasis& basis) {
  assert(out_positions.size() >= 3 * joints.size());
  assert(out_quaternions.empty() || out_quaternions.size() >= 4 * joints.size());
  if (viewer < 0 && basis.identity && out_quaternions.empty()) {
    // World positions in native conventions (most streams): what the loop
    // below gives, float to double and back unchanged, without the trip
    // (view/world_positions: 297 -> 101 ns for 38 joints).
    // Copied run by run of consecutive joints (all of them, in order, is one run).
    for (std::size_t i = 0; i < joints.size();) {
      std::size_t end = i + 1;
      while (end < joints.size() && joints[end] == joints[end - 1] + 1) ++end;
      const auto j = static_cast<std::size_t>(joints[i]);
      assert(fk_positions.size() >= 3 * (j + end - i));
      std::memcpy(out_positions.data() + 3 * i, fk_positions.data() + 3 * j, 3 * (end - i) * sizeof(float));
      i = end;
    }
    return;
  }
  const Viewpoint from =
      viewer < 0 ? Viewpoint() : Viewpoint::of_joint(fk_positions, fk_orientations, static_cast<std::size_t>(viewer));
  if (basis.identity) {
    view_joints<false>(fk_positions, fk_orientations, from, joints, out_positions, out_quaternions, basis);
  } else {
    view_joints<true>(fk_positions, fk_orientations, from, joints, out_positions, out_quaternions, basis);
  }
}

}  // namespace gmr
