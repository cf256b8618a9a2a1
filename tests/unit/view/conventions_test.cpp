// Engine conventions: each preset against what its engine's documentation
// says, worked out by hand, and back again.
#include "gmr/view/conventions.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

namespace gmr {
namespace {

constexpr double kPi = 3.14159265358979323846;

OutputBasis basis(ConventionPreset p, double source_metres_per_unit = 0.0) {
  Conventions c;
  c.preset = p;
  c.source_metres_per_unit = source_metres_per_unit;
  return output_basis(c).value();
}

// Source axes (BVH habit): +X the character's left, +Y up, +Z forward.
// A point 1 to the left, 2 up and 3 ahead, in each engine's axes.
TEST(Conventions, PresetsPutLeftUpAndForwardWhereEachEngineHasThem) {
  const Eigen::Vector3d p(1, 2, 3);
  EXPECT_EQ(basis(ConventionPreset::kNative).position(p), p);
  EXPECT_TRUE(basis(ConventionPreset::kNative).identity);
  // Unreal: X forward, Y right (left is -Y), Z up; centimetres.
  EXPECT_EQ(basis(ConventionPreset::kUnreal, 1.0).position(p), Eigen::Vector3d(300, -100, 200));
  EXPECT_EQ(basis(ConventionPreset::kUnreal).position(p), Eigen::Vector3d(3, -1, 2)) << "unknown unit: none applied";
  // Unity: X right (left is -X), Y up, Z forward.
  EXPECT_EQ(basis(ConventionPreset::kUnity).position(p), Eigen::Vector3d(-1, 2, 3));
  // Blender: Z up, -Y forward (its front view looks along +Y), X the character's left seen from the front.
  EXPECT_EQ(basis(ConventionPreset::kBlender).position(p), Eigen::Vector3d(1, -3, 2));
  // Godot: Y up, -Z forward, X right (left is -X).
  EXPECT_EQ(basis(ConventionPreset::kGodot).position(p), Eigen::Vector3d(-1, 2, -3));
  // Handedness: the two left-handed presets mirror.
  EXPECT_DOUBLE_EQ(basis(ConventionPreset::kUnreal).b.determinant(), -1.0);
  EXPECT_DOUBLE_EQ(basis(ConventionPreset::kUnity).b.determinant(), -1.0);
  EXPECT_DOUBLE_EQ(basis(ConventionPreset::kBlender).b.determinant(), 1.0);
  EXPECT_DOUBLE_EQ(basis(ConventionPreset::kGodot).b.determinant(), 1.0);
  // Inches to centimetres.
  EXPECT_NEAR(basis(ConventionPreset::kUnreal, 0.0254).scale, 2.54, 1e-15);
}

// A turn from facing forward to facing left (90 degrees about up in the
// source) is, in every engine, a proper rotation that keeps its up axis and
// takes its forward axis to its left; in Unity, whose positive turns about Y
// go clockwise seen from above, that is Quaternion.Euler(0, -90, 0).
TEST(Conventions, OrientationsTurnTheSameWayInEveryEngine) {
  const Eigen::Matrix3d turn_left = Eigen::AngleAxisd(kPi / 2, Eigen::Vector3d::UnitY()).toRotationMatrix();
  ASSERT_TRUE((turn_left * Eigen::Vector3d::UnitZ()).isApprox(Eigen::Vector3d::UnitX()));
  struct Engine {
    ConventionPreset preset;
    Eigen::Vector3d up, forward, left;
  };
  const Engine engines[] = {
      {ConventionPreset::kUnreal, {0, 0, 1}, {1, 0, 0}, {0, -1, 0}},
      {ConventionPreset::kUnity, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}},
      {ConventionPreset::kBlender, {0, 0, 1}, {0, -1, 0}, {1, 0, 0}},
      {ConventionPreset::kGodot, {0, 1, 0}, {0, 0, -1}, {-1, 0, 0}},
  };
  for (const Engine& e : engines) {
    SCOPED_TRACE(std::string(preset_name(e.preset)));
    const Eigen::Matrix3d w = basis(e.preset).orientation(turn_left);
    EXPECT_NEAR(w.determinant(), 1.0, 1e-15);
    EXPECT_TRUE((w * e.up).isApprox(e.up, 1e-15));
    EXPECT_TRUE((w * e.forward).isApprox(e.left, 1e-15));
  }
  const Eigen::Quaterniond q(basis(ConventionPreset::kUnity).orientation(turn_left));
  const double h = std::sqrt(0.5);
  EXPECT_NEAR(std::abs(q.y()), h, 1e-15);
  EXPECT_NEAR(q.y() * q.w(), -0.5, 1e-15) << "-90 degrees about Y";
  EXPECT_NEAR(q.x(), 0.0, 1e-15);
  EXPECT_NEAR(q.z(), 0.0, 1e-15);
}

// Back again: p = B^T p' / s and W = B^T W' B, for every preset.
TEST(Conventions, RoundTrip) {
  const Eigen::Vector3d p(0.3, -1.7, 2.9);
  const Eigen::Matrix3d w = (Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()) *
                             Eigen::AngleAxisd(-1.1, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  for (ConventionPreset pr :
       {ConventionPreset::kUnreal, ConventionPreset::kUnity, ConventionPreset::kBlender, ConventionPreset::kGodot}) {
    const OutputBasis b = basis(pr, 0.0254);
    EXPECT_TRUE((b.b.transpose() * b.position(p) / b.scale).isApprox(p, 1e-15)) << preset_name(pr);
    EXPECT_TRUE((b.b.transpose() * b.orientation(w) * b.b).isApprox(w, 1e-15)) << preset_name(pr);
    // The quaternion form is the matrix form.
    const Eigen::Quaterniond q = b.orientation(Eigen::Quaterniond(w));
    EXPECT_TRUE(q.toRotationMatrix().isApprox(b.orientation(w), 1e-14)) << preset_name(pr);
    // Positions and orientations agree: a joint's frame moves points as positions do.
    const Eigen::Vector3d d(0.5, 0.25, -1);
    EXPECT_TRUE(b.position(w * d).isApprox(b.orientation(w) * b.position(d), 1e-14)) << preset_name(pr);
  }
}

TEST(Conventions, CustomAndItsErrors) {
  Conventions c;
  c.preset = ConventionPreset::kCustom;
  c.up = 3;
  c.forward = 1;
  c.left_handed = true;
  c.target_metres_per_unit = 0.01;
  c.source_metres_per_unit = 1.0;
  const OutputBasis custom = output_basis(c).value();
  EXPECT_EQ(custom.b, basis(ConventionPreset::kUnreal).b) << "custom Z up, X forward, left-handed, cm is Unreal";
  EXPECT_EQ(custom.scale, 100.0);
  c.forward = -3;
  EXPECT_FALSE(output_basis(c).ok()) << "up and forward on one axis";
  c.forward = 4;
  EXPECT_FALSE(output_basis(c).ok());
  c.forward = 1;
  c.target_metres_per_unit = 0.0;
  EXPECT_FALSE(output_basis(c).ok());
  c.target_metres_per_unit = 1.0;
  c.source_metres_per_unit = -2.0;
  EXPECT_FALSE(output_basis(c).ok());
  for (const char* name : {"native", "unreal", "unity", "blender", "godot", "custom"}) {
    ASSERT_TRUE(preset_named(name).has_value()) << name;
    EXPECT_EQ(preset_name(*preset_named(name)), name);
  }
  EXPECT_FALSE(preset_named("maya").has_value());
}

}  // namespace
}  // namespace gmr
