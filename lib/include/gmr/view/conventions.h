// Engine conventions: positions and orientations in the axes, handedness and
// unit an engine uses (docs/protocol.md, "Conventions").
//
// gmr's motions are in their file's axes; the presets assume the BVH and
// Acclaim habit: Y up, the character facing +Z, right-handed (so its left is
// +X). A target is its up axis, its forward axis and its handedness; its side
// axis (where the character's left goes) is up x forward, mirrored for a
// left-handed target. With B the matrix whose columns are the target's side,
// up and forward axes, and s = source metres per unit / target metres per unit,
//
//   p' = s B p        W' = B W B^T
//
// for every position p and orientation W (B W B^T is a proper rotation even
// when det B = -1: the mirror acts on both sides, so a quaternion read in the
// target's own axes turns the way the motion does).
//
//   preset    up   forward  handedness  unit
//   native    (as in the file: nothing changes)
//   unreal    +Z   +X       left        cm
//   unity     +Y   +Z       left        m
//   blender   +Z   -Y       right       m
//   godot     +Y   -Z       right       m
//
// Units change only when the motion's own unit is known
// (source_metres_per_unit); otherwise positions keep the motion's units.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <optional>
#include <string_view>

#include "gmr/core/error.h"

namespace gmr {

enum class ConventionPreset { kNative, kUnreal, kUnity, kBlender, kGodot, kCustom };

struct Conventions {
  ConventionPreset preset = ConventionPreset::kNative;
  // kCustom only: signed axes, 1 = +X, 2 = +Y, 3 = +Z, -1 = -X, ...
  int up = 2;
  int forward = 3;
  bool left_handed = false;
  double target_metres_per_unit = 1.0;
  // The motion's unit in metres (0.0254 for inches); 0: unknown, no unit change.
  double source_metres_per_unit = 0.0;
};

// B and s of a convention. Identity (and scale 1) for native.
struct OutputBasis {
  Eigen::Matrix3d b = Eigen::Matrix3d::Identity();
  double scale = 1.0;
  bool identity = true;  // b = I and scale = 1: nothing to do
  bool mirror = false;   // det b = -1 (a left-handed target)
  // The unit of the positions it gives, in metres: the target's when the
  // motion's unit is known, the motion's own with native conventions, 0 when
  // it is unknown (the numbers stay in the motion's units, whatever they are).
  double metres_per_unit = 0.0;

  Eigen::Vector3d position(const Eigen::Vector3d& p) const { return identity ? p : Eigen::Vector3d(scale * (b * p)); }
  Eigen::Matrix3d orientation(const Eigen::Matrix3d& w) const {
    return identity ? w : Eigen::Matrix3d(b * w * b.transpose());
  }
  // The same for a rotation as a quaternion (w, v): B W B^T turns by the same
  // angle about B n, so it is (w, B v), or (w, -B v) when B mirrors (-B is
  // then the proper rotation with the same conjugation).
  Eigen::Quaterniond orientation(const Eigen::Quaterniond& q) const {
    if (identity) return q;
    const Eigen::Vector3d v = b * q.vec();
    return mirror ? Eigen::Quaterniond(q.w(), -v.x(), -v.y(), -v.z()) : Eigen::Quaterniond(q.w(), v.x(), v.y(), v.z());
  }
};

// Fails for a custom convention whose axes are not +-1..3, or whose up and
// forward are parallel, and for units that are not positive and finite
// (source 0 is allowed: unknown).
Result<OutputBasis> output_basis(const Conventions& c);

// "native", "unreal", "unity", "blender", "godot" (and "custom").
std::string_view preset_name(ConventionPreset p);
std::optional<ConventionPreset> preset_named(std::string_view name);

}  // namespace gmr
