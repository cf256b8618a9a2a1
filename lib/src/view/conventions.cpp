#include "gmr/view/conventions.h"

#include <Eigen/Geometry>
#include <cmath>
#include <string>

namespace gmr {
namespace {

struct Target {
  int up, forward;
  bool left_handed;
  double metres_per_unit;
};

Target target_of(const Conventions& c) {
  switch (c.preset) {
    case ConventionPreset::kUnreal:
      return {3, 1, true, 0.01};
    case ConventionPreset::kUnity:
      return {2, 3, true, 1.0};
    case ConventionPreset::kBlender:
      return {3, -2, false, 1.0};
    case ConventionPreset::kGodot:
      return {2, -3, false, 1.0};
    case ConventionPreset::kCustom:
      return {c.up, c.forward, c.left_handed, c.target_metres_per_unit};
    case ConventionPreset::kNative:
      break;
  }
  return {2, 3, false, 1.0};  // the source's own axes
}

Eigen::Vector3d axis(int a) {
  Eigen::Vector3d v = Eigen::Vector3d::Zero();
  v[std::abs(a) - 1] = a > 0 ? 1.0 : -1.0;
  return v;
}

bool positive_finite(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace

Result<OutputBasis> output_basis(const Conventions& c) {
  OutputBasis out;
  if (c.source_metres_per_unit > 0.0) out.metres_per_unit = c.source_metres_per_unit;
  if (c.preset == ConventionPreset::kNative) return out;
  const Target t = target_of(c);
  if (t.up == 0 || t.forward == 0 || std::abs(t.up) > 3 || std::abs(t.forward) > 3) {
    return make_error("conventions: up and forward must be one of +X, -X, +Y, -Y, +Z, -Z");
  }
  if (std::abs(t.up) == std::abs(t.forward)) return make_error("conventions: up and forward must be different axes");
  if (!positive_finite(t.metres_per_unit)) return make_error("conventions: the target unit must be a positive length");
  if (c.source_metres_per_unit != 0.0 && !positive_finite(c.source_metres_per_unit)) {
    return make_error("conventions: the motion's unit must be a positive length (0: unknown)");
  }
  const Eigen::Vector3d up = axis(t.up), forward = axis(t.forward);
  Eigen::Vector3d side = up.cross(forward);
  if (t.left_handed) side = -side;
  // Source: side +X, up +Y, forward +Z; so B's columns are the target's side, up, forward.
  out.b.col(0) = side;
  out.b.col(1) = up;
  out.b.col(2) = forward;
  out.scale = c.source_metres_per_unit > 0.0 ? c.source_metres_per_unit / t.metres_per_unit : 1.0;
  out.metres_per_unit = c.source_metres_per_unit > 0.0 ? t.metres_per_unit : 0.0;
  out.identity = out.b == Eigen::Matrix3d::Identity() && out.scale == 1.0;
  out.mirror = out.b.determinant() < 0.0;
  return out;
}

std::string_view preset_name(ConventionPreset p) {
  switch (p) {
    case ConventionPreset::kNative:
      return "native";
    case ConventionPreset::kUnreal:
      return "unreal";
    case ConventionPreset::kUnity:
      return "unity";
    case ConventionPreset::kBlender:
      return "blender";
    case ConventionPreset::kGodot:
      return "godot";
    case ConventionPreset::kCustom:
      return "custom";
  }
  return "native";
}

std::optional<ConventionPreset> preset_named(std::string_view name) {
  for (ConventionPreset p : {ConventionPreset::kNative, ConventionPreset::kUnreal, ConventionPreset::kUnity,
                             ConventionPreset::kBlender, ConventionPreset::kGodot, ConventionPreset::kCustom}) {
    if (preset_name(p) == name) return p;
  }
  return std::nullopt;
}

}  // namespace gmr
