// Private: the Acclaim model's per-bone algebra (gmr/acclaim/kinematics.h
// states it), shared by the forward kinematics and the conversions.
#pragma once

#include <Eigen/Core>
#include <numbers>
#include <span>
#include <vector>

#include "gmr/acclaim/amc.h"
#include "gmr/acclaim/asf.h"
#include "gmr/core/rotation.h"

namespace gmr::acclaim_detail {

inline constexpr double kRadToDeg = 180.0 / std::numbers::pi;

inline bool is_rotation_dof(AcclaimDof d) {
  return d == AcclaimDof::kRx || d == AcclaimDof::kRy || d == AcclaimDof::kRz;
}
inline bool is_translation_dof(AcclaimDof d) {
  return d == AcclaimDof::kTx || d == AcclaimDof::kTy || d == AcclaimDof::kTz;
}
// Axis of an rx/ry/rz or tx/ty/tz dof.
inline Axis dof_axis(AcclaimDof d) {
  switch (d) {
    case AcclaimDof::kRx:
    case AcclaimDof::kTx:
      return Axis::kX;
    case AcclaimDof::kRy:
    case AcclaimDof::kTy:
      return Axis::kY;
    default:
      return Axis::kZ;
  }
}

inline bool has_axis(const AsfBone& b) { return b.axis != Eigen::Vector3d::Zero(); }

inline bool has_translation(const AsfBone& b) {
  for (AcclaimDof d : b.dofs) {
    if (is_translation_dof(d) || d == AcclaimDof::kL) return true;
  }
  return false;
}

// C: the axis angles applied in axis_order, so "XYZ" gives Rz * Ry * Rx.
inline Eigen::Matrix3d axis_frame(const AsfBone& b, double to_degrees) {
  Eigen::Matrix3d c = Eigen::Matrix3d::Identity();
  if (!has_axis(b)) return c;
  for (Axis a : b.axis_order) c = axis_rotation(a, b.axis[static_cast<int>(a)] * to_degrees) * c;
  return c;
}

// What every frame of a skeleton shares: value layout and axis frames C.
struct Prepared {
  std::vector<int> offsets;        // first AMC value of each bone within a frame
  std::size_t stride = 0;          // AMC values per frame
  std::vector<Eigen::Matrix3d> c;  // C of each bone
};

inline Prepared prepare(const AsfSkeleton& s) {
  Prepared p;
  p.offsets.resize(s.bones.size());
  p.c.resize(s.bones.size());
  const double axis_scale = s.units.degrees ? 1.0 : kRadToDeg;
  int n = 0;
  for (std::size_t b = 0; b < s.bones.size(); ++b) {
    p.offsets[b] = n;
    n += static_cast<int>(s.bones[b].dofs.size());
    p.c[b] = axis_frame(s.bones[b], axis_scale);
  }
  p.stride = static_cast<std::size_t>(n);
  return p;
}

// The parts of one bone's local transform for one frame.
struct BoneState {
  Eigen::Matrix3d local;      // L = C M C^-1
  Eigen::Vector3d t;          // (tx, ty, tz), in C's frame (the root: world)
  double extra_length = 0.0;  // l
};

inline BoneState bone_state(const AsfBone& b, const Eigen::Matrix3d& c, std::span<const double> v, bool amc_degrees) {
  const double value_scale = amc_degrees ? 1.0 : kRadToDeg;
  BoneState st;
  st.t.setZero();
  Eigen::Matrix3d m = Eigen::Matrix3d::Identity();
  for (std::size_t i = 0; i < b.dofs.size(); ++i) {
    const AcclaimDof d = b.dofs[i];
    if (is_rotation_dof(d)) {
      m = axis_rotation(dof_axis(d), v[i] * value_scale) * m;  // dofs apply first to last
    } else if (is_translation_dof(d)) {
      st.t[static_cast<int>(dof_axis(d))] = v[i];
    } else {
      st.extra_length = v[i];
    }
  }
  st.local = has_axis(b) ? Eigen::Matrix3d(c * m * c.transpose()) : m;
  return st;
}

inline std::span<const double> bone_values(const AsfSkeleton& s, const AmcMotion& m, std::size_t frame, int b,
                                           const Prepared& prep) {
  return std::span<const double>(m.values).subspan(
      frame * prep.stride + static_cast<std::size_t>(prep.offsets[static_cast<std::size_t>(b)]),
      s.bones[static_cast<std::size_t>(b)].dofs.size());
}

inline void compute_frame_impl(const AsfSkeleton& s, const AmcMotion& m, std::size_t frame, const Prepared& prep,
                               std::vector<Eigen::Matrix3d>& world, std::span<Eigen::Vector3d> pos,
                               std::span<Eigen::Matrix3d> rot) {
  world.resize(s.bones.size());
  for (std::size_t b = 0; b < s.bones.size(); ++b) {
    const AsfBone& bone = s.bones[b];
    const BoneState st = bone_state(bone, prep.c[b], bone_values(s, m, frame, static_cast<int>(b), prep), m.degrees);
    if (bone.parent < 0) {
      world[b] = st.local;
      pos[b] = bone.position + st.t;
    } else {
      const auto p = static_cast<std::size_t>(bone.parent);
      world[b] = world[p] * st.local;
      pos[b] = pos[p] + world[p] * (prep.c[b] * st.t) + world[b] * (bone.direction * (bone.length + st.extra_length));
    }
    if (!rot.empty()) rot[b] = world[b];
  }
}

}  // namespace gmr::acclaim_detail
