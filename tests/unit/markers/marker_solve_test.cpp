// From raw markers to a GMR motion: the model format, the solver's math on
// synthetic markers with known joint centres, and CMU's C3D takes against
// their own AMC motions.
#include "gmr/markers/marker_solve.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "gmr/io/motion_file.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/markers/marker_model.h"
#include "gmr/ops/set_roots.h"
#include "markers_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {

using Eigen::Matrix3d;
using Eigen::Quaterniond;
using Eigen::Vector3d;

// ---- the model format

TEST(MarkerModel, BuiltinCmu41ParsesWithTheAsfBoneNamesAndEveryMarker) {
  auto m = builtin_marker_model("cmu41");
  ASSERT_TRUE(m.ok()) << m.error().to_string();
  EXPECT_EQ(m->name, "cmu41");
  for (const char* bone : {"root", "lhipjoint", "lfemur", "ltibia", "rhipjoint", "rfemur", "rtibia", "lclavicle",
                           "lhumerus", "lradius", "rclavicle", "rhumerus", "rradius", "thorax", "head"}) {
    EXPECT_GE(m->find_joint(bone), 0) << bone;
  }
  const std::vector<std::string> markers = m->marker_names();
  EXPECT_EQ(markers.size(), 41u);
  for (const char* name : {"LFHD", "RBAC", "LWRB", "RMT5", "C7", "T10", "STRN", "LFIN", "RHEE"}) {
    EXPECT_NE(std::find(markers.begin(), markers.end(), name), markers.end()) << name;
  }
  // `builtin NAME` as a model file's whole text.
  auto b = parse_marker_model("# the CMU set\nbuiltin cmu41\n", "x.model");
  ASSERT_TRUE(b.ok()) << b.error().to_string();
  EXPECT_EQ(b->joints.size(), m->joints.size());
}

TEST(MarkerModel, ErrorsSayWhereAndWhat) {
  const std::string head = "gmr-marker-model 1\npart a M1 M2 M3\npart b j M4 M5\n";
  struct Case {
    std::string text;
    std::string where;
    std::string what;
  };
  const std::vector<Case> cases = {
      {"part a M1 M2\n", "m:1:1", "expected 'gmr-marker-model 1'"},
      {"gmr-marker-model 2\n", "m:1:1", "version 2"},
      {head + "joint j in a at mean(M1, M2\n", "m:4:", "expected ',' or ')'"},
      {head + "joint j in c at M1\n", "m:4:1", "unknown part 'c'"},
      {head + "joint j parent k in a at M1\n", "m:4:1", "parent 'k' is not a joint defined above"},
      {head + "joint j in a at along(M1, M2, M3, 5furlongs)\n", "m:4:", "'5furlongs'"},
      {head + "joint j in a at M1 M2\n", "m:4:", "unexpected 'M2'"},
      {head + "joint j in a centre a prior M1\n", "m:4:1", "within the same part"},
      {head + "joint k in b at M4\njoint j parent k in a at M1\n", "m:4", "uses joint 'j'"},
      {head + "frobnicate\n", "m:4:1", "unknown statement 'frobnicate'"},
      {head + "part a M6 M7\n", "m:4:1", "part 'a' is defined twice"},
      {head + "joint j in a at M1\njoint j in a at M2\n", "m:5:1", "joint 'j' is defined twice"},
      {head + "outlier 40\n", "m:4:9", "outlier takes a length in mm, cm or m"},
      {head + "min-relative-spread 0.3x\n", "m:4:21", "'0.3x' is not a number"},
      {"gmr-marker-model 1\npart a M1 M2\njoint j in a at M1\n", "m:2", "the first must be a joint"},
      {"gmr-marker-model 1\npart a M1 M1 M2\n", "m:2:", "lists 'M1' twice"},
      {"gmr-marker-model 1\npart a M1*0 M2 M3\n", "m:2:", "weight must be positive"},
      {head + "joint j in a at M1 split\n", "m:4:", "expected the joint at the chain's end"},
      {head + "joint j in a at M1 split k\n", "m:4:", "expected the fraction of the chain's length"},
      {head + "joint j in a at M1 split k 1.5\n", "m:4:", "between 0 and 1"},
      {head + "joint j in a at M1\njoint k parent j in b at M4 split j 0.5\n", "m:5", "must be a joint below it"},
      {head + "joint j in a at M1 split k 0.5\njoint k parent j in b at M4\n", "m:4", "needs a parent"},
      {head + "joint r in a at M1\njoint j parent r in a at M2 split q 0.5\n", "m:5", "'q'"},
      {"builtin cmu99\n", "m", "no built-in marker model 'cmu99'"},
      {"gmr-marker-model 1\nbuiltin cmu41\n", "m", "only statement"},
  };
  for (const Case& c : cases) {
    auto r = parse_marker_model(c.text, "m");
    ASSERT_FALSE(r.ok()) << c.text;
    const std::string s = r.error().to_string();
    EXPECT_EQ(s.rfind(c.where, 0), 0u) << s << "\nfor:\n" << c.text;
    EXPECT_NE(s.find(c.what), std::string::npos) << s << "\nfor:\n" << c.text;
  }
}

TEST(MarkerModel, SubjectPrefixesAreStripped) {
  EXPECT_EQ(strip_subject_prefix("TakeoMonday:LKNE"), "LKNE");
  EXPECT_EQ(strip_subject_prefix("LKNE"), "LKNE");
  EXPECT_EQ(strip_subject_prefix("a:b:RTOE"), "RTOE");
}

// ---- synthetic markers: a three-part chain with known centres

// base (4 markers) -> ball joint J1 -> arm (2 markers + J1) -> joint J2 ->
// fore (3 markers + J2). The base wanders and turns; the arm turns about J1
// on all three axes; the fore turns about J2 on all axes (ball) or on one
// (hinge).
struct Synthetic {
  MarkerTrajectories markers;
  std::vector<Vector3d> j1, j2;  // true world positions per frame
};

Synthetic make_synthetic(bool hinge, std::size_t frames) {
  Synthetic s;
  s.markers.names = {"B1", "B2", "B3", "B4", "A1", "A2", "F1", "F2", "F3"};
  s.markers.units = "mm";
  s.markers.frame_rate = 100;
  s.markers.frame_count = frames;
  const Vector3d base_m[4] = {{-100, 50, 0}, {100, 50, 0}, {-80, -60, 20}, {90, -70, -10}};
  const Vector3d j1_in_base(30, -20, -150);
  const Vector3d arm_m[2] = {{40, 10, -200}, {-20, 60, -380}};  // relative to J1
  const Vector3d j2_in_arm(0, 0, -420);
  const Vector3d fore_m[3] = {{30, 0, -100}, {-40, 35, -250}, {0, -30, -400}};  // relative to J2
  for (std::size_t f = 0; f < frames; ++f) {
    const double t = static_cast<double>(f) / 100.0;
    const Matrix3d rb = (Eigen::AngleAxisd(0.3 * std::sin(0.7 * t), Vector3d::UnitZ()) *
                         Eigen::AngleAxisd(0.2 * std::sin(1.1 * t), Vector3d::UnitX()))
                            .toRotationMatrix();
    const Vector3d tb(200 * std::sin(0.5 * t), 100 * t, 900 + 30 * std::sin(2 * t));
    const Matrix3d ra = rb * (Eigen::AngleAxisd(0.8 * std::sin(1.3 * t), Vector3d::UnitX()) *
                              Eigen::AngleAxisd(0.6 * std::sin(0.9 * t + 1), Vector3d::UnitY()) *
                              Eigen::AngleAxisd(0.5 * std::sin(1.7 * t), Vector3d::UnitZ()))
                                 .toRotationMatrix();
    const Matrix3d rf =
        ra * (hinge ? Eigen::AngleAxisd(0.9 + 0.8 * std::sin(2.1 * t), Vector3d::UnitX()).toRotationMatrix()
                    : (Eigen::AngleAxisd(0.9 * std::sin(2.1 * t), Vector3d::UnitX()) *
                       Eigen::AngleAxisd(0.7 * std::sin(1.3 * t + 2), Vector3d::UnitY()) *
                       Eigen::AngleAxisd(0.6 * std::sin(0.8 * t), Vector3d::UnitZ()))
                          .toRotationMatrix());
    const Vector3d p1 = tb + rb * j1_in_base;
    const Vector3d p2 = p1 + ra * j2_in_arm;
    s.j1.push_back(p1);
    s.j2.push_back(p2);
    std::vector<Vector3d> m;
    for (const Vector3d& b : base_m) m.push_back(tb + rb * b);
    for (const Vector3d& a : arm_m) m.push_back(p1 + ra * a);
    for (const Vector3d& c : fore_m) m.push_back(p2 + rf * c);
    for (const Vector3d& v : m) s.markers.positions.insert(s.markers.positions.end(), {v.x(), v.y(), v.z()});
  }
  return s;
}

constexpr const char* kChainModel = R"(gmr-marker-model 1
name chain
part base B1 B2 B3 B4
part arm j1 A1 A2
part fore j2 F1 F2 F3
joint root in base at mean(B1, B2, B3, B4)
joint j1 parent root in base centre arm prior along(mean(B1, B2, B3, B4), B1, B2, 25mm)
joint j2 parent j1 in arm centre fore prior along(A2, A2, A1, 0.1)
joint tip parent j2 in fore at F3
)";

std::vector<Vector3d> joint_track(const Motion& m, const std::string& name) {
  const int j = m.skeleton.find(name);
  std::vector<Vector3d> out;
  const auto all = compute_positions(m);
  for (std::size_t f = 0; f < m.frame_count; ++f)
    out.push_back(all[f * m.skeleton.size() + static_cast<std::size_t>(j)]);
  return out;
}

double median_distance(const std::vector<Vector3d>& a, const std::vector<Vector3d>& b) {
  std::vector<double> d;
  for (std::size_t i = 0; i < a.size(); ++i) d.push_back((a[i] - b[i]).norm());
  std::nth_element(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(d.size() / 2), d.end());
  return d[d.size() / 2];
}

double max_distance(const std::vector<Vector3d>& a, const std::vector<Vector3d>& b) {
  double d = 0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::max(d, (a[i] - b[i]).norm());
  return d;
}

TEST(MarkerSolve, BallJointsAreFoundExactlyFromTheMotionAlone) {
  const Synthetic s = make_synthetic(false, 600);
  auto model = parse_marker_model(kChainModel, "chain");
  ASSERT_TRUE(model.ok()) << model.error().to_string();
  auto r = solve_markers(s.markers, *model);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  // Every direction is determined by the motion: the priors (25 mm and more
  // off) play no part, and the centres are exact.
  for (const char* j : {"j1", "j2"}) {
    const JointFit& jf = r->joints[static_cast<std::size_t>(model->find_joint(j))];
    EXPECT_TRUE(jf.functional);
    EXPECT_EQ(jf.determined, 3) << j;
    EXPECT_LT(jf.fit_rms, 1e-6) << j;
    EXPECT_GT(jf.prior_distance, 10.0) << j;
  }
  EXPECT_LT(max_distance(joint_track(r->motion, "j1"), s.j1), 1e-6);
  EXPECT_LT(max_distance(joint_track(r->motion, "j2"), s.j2), 1e-6);
  // tip is placed `at F3`: it follows that marker.
  std::vector<Vector3d> f3;
  for (std::size_t f = 0; f < s.markers.frame_count; ++f) {
    f3.emplace_back(s.markers.positions[s.markers.index(f, 8)], s.markers.positions[s.markers.index(f, 8, 1)],
                    s.markers.positions[s.markers.index(f, 8, 2)]);
  }
  EXPECT_LT(max_distance(joint_track(r->motion, "tip"), f3), 1e-6);
  // Rigid parts: every bone is constant, every marker is carried exactly.
  for (const JointFit& jf : r->joints) EXPECT_LT(jf.bone_rms, 1e-6) << jf.name;
  for (const PartFit& p : r->parts) {
    EXPECT_EQ(p.fitted, 600u) << p.name;
    EXPECT_LT(p.fit_rms, 1e-6) << p.name;
    EXPECT_LT(p.motion_max, 1e-6) << p.name;
  }
  ASSERT_EQ(r->carried.size(), 9u);
  const auto carried = carried_marker_positions(r->motion, r->carried, 123);
  for (std::size_t i = 0; i < carried.size(); ++i) {
    const std::size_t m = static_cast<std::size_t>(r->carried[i].marker_index);
    const Vector3d measured(s.markers.positions[s.markers.index(123, m)],
                            s.markers.positions[s.markers.index(123, m, 1)],
                            s.markers.positions[s.markers.index(123, m, 2)]);
    EXPECT_LT((carried[i] - measured).norm(), 1e-6) << r->carried[i].marker;
  }
  // Pre-rotation and no dummy joint: j1 shares its parent's part, so it has
  // no channels; the root holds the positions.
  const Skeleton& sk = r->motion.skeleton;
  EXPECT_EQ(r->motion.convention, Convention::kPreRotation);
  EXPECT_TRUE(sk.joint(sk.find("j1")).channels.empty());
  EXPECT_EQ(sk.joint(sk.find("j2")).channels.size(), 3u);
  EXPECT_EQ(sk.joint(sk.find("root")).channels.size(), 6u);
  EXPECT_DOUBLE_EQ(r->motion.frame_time, 0.01);
}

// Units: the same take in metres gives the same motion in metres (lengths
// in the model, outliers and spreads are millimetres, converted).
TEST(MarkerSolve, MarkersInMetresGiveTheSameMotionInMetres) {
  const Synthetic s = make_synthetic(false, 400);
  MarkerTrajectories metres = s.markers;
  metres.units = "m";
  for (double& v : metres.positions) v /= 1000;
  auto model = parse_marker_model(kChainModel, "chain");
  ASSERT_TRUE(model.ok());
  auto mm = solve_markers(s.markers, *model);
  auto m = solve_markers(metres, *model);
  ASSERT_TRUE(mm.ok() && m.ok());
  EXPECT_EQ(m->millimetres_per_unit, 1000);
  const auto a = compute_positions(mm->motion);
  const auto b = compute_positions(m->motion);
  ASSERT_EQ(a.size(), b.size());
  double worst = 0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, (a[i] / 1000 - b[i]).norm());
  EXPECT_LT(worst, 1e-9);
  for (std::size_t j = 0; j < mm->joints.size(); ++j) EXPECT_EQ(mm->joints[j].determined, m->joints[j].determined);
  // A file without units is taken as millimetres, with a warning.
  MarkerTrajectories none = s.markers;
  none.units.clear();
  auto n = solve_markers(none, *model);
  ASSERT_TRUE(n.ok());
  ASSERT_EQ(n->warnings.size(), 1u);
  EXPECT_NE(n->warnings[0].message.find("millimetres assumed"), std::string::npos);
}

TEST(MarkerSolve, AHingeCentreIsTheAxisPointNearestThePrior) {
  const Synthetic s = make_synthetic(true, 600);
  auto model = parse_marker_model(kChainModel, "chain");
  ASSERT_TRUE(model.ok());
  auto r = solve_markers(s.markers, *model);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const JointFit& j2 = r->joints[static_cast<std::size_t>(model->find_joint("j2"))];
  EXPECT_EQ(j2.determined, 2);  // the hinge axis (x of the arm) is not
  // The prior along(A2, A2, A1, 0.1) in the arm's frame: its x coordinate
  // (relative to J2) is what the solution keeps; the other two are J2's.
  const Vector3d a1(40, 10, -200), a2(-20, 60, -380), j2_in_arm(0, 0, -420);
  const Vector3d prior = a2 + 0.1 * (a1 - a2);
  const double along_axis = prior.x() - j2_in_arm.x();
  const std::vector<Vector3d> found = joint_track(r->motion, "j2");
  for (std::size_t f = 0; f < s.j2.size(); f += 50) {
    EXPECT_NEAR((found[f] - s.j2[f]).norm(), std::abs(along_axis), 1e-6) << f;
  }
  EXPECT_NEAR(j2.prior_distance, std::hypot(prior.y() - j2_in_arm.y(), prior.z() - j2_in_arm.z()), 1e-6);

  // Marked `hinge`, the joint takes one direction from the take (the one the
  // flexion sweeps most) and the other two from the prior: the result moves
  // toward the prior, and keeps the determined coordinate.
  std::string text = kChainModel;
  text.replace(text.find("centre fore prior"), 17, "centre fore hinge prior");
  auto hinged = parse_marker_model(text, "chain");
  ASSERT_TRUE(hinged.ok()) << hinged.error().to_string();
  EXPECT_TRUE(hinged->joints[static_cast<std::size_t>(hinged->find_joint("j2"))].hinge);
  auto h = solve_markers(s.markers, *hinged);
  ASSERT_TRUE(h.ok()) << h.error().to_string();
  const JointFit& hj = h->joints[static_cast<std::size_t>(hinged->find_joint("j2"))];
  EXPECT_EQ(hj.determined, 1);
  EXPECT_LT(hj.prior_distance, j2.prior_distance);
  // The point found is fixed in the arm (a constant distance from the true
  // centre) and nearer the truth than the prior, one coordinate being exact.
  const std::vector<Vector3d> hinged_found = joint_track(h->motion, "j2");
  const double off = (hinged_found[0] - s.j2[0]).norm();
  EXPECT_LT(off, (prior - j2_in_arm).norm());
  EXPECT_GT(off, std::abs(along_axis));
  for (std::size_t f = 0; f < s.j2.size(); f += 50) EXPECT_NEAR((hinged_found[f] - s.j2[f]).norm(), off, 1e-6) << f;
}

// `split tip FRACTION` slides j2 along the line from j1 until j1 -> j2 is
// FRACTION of j1 -> j2 -> tip. Here j2 is placed 40 mm too far down the arm
// (by its markers alone, no centre fit) and the fore has its own three
// markers: with the chain's true proportion the split finds j2 exactly; a
// fraction that would move it past half its bone leaves it, with a warning.
TEST(MarkerSolve, ASplitPutsAJointAtItsChainsProportion) {
  const Synthetic s = make_synthetic(false, 600);
  // 40 mm below the true j2 (0, 0, -420 from j1 in the arm), in the frame
  // local(j1, A2, A1, ...) gives: x toward A2, z = x cross A1, y = z cross x.
  const Vector3d a1(40, 10, -200), a2(-20, 60, -380), off(0, 0, -460);
  const Vector3d x = a2.normalized(), z = x.cross(a1).normalized(), y = z.cross(x);
  auto model_text = [&](const std::string& split) {
    char j2[160];
    std::snprintf(j2, sizeof j2, "joint j2 parent j1 in arm at local(j1, A2, A1, %.9fmm, %.9fmm, %.9fmm)%s\n",
                  off.dot(x), off.dot(y), off.dot(z), split.c_str());
    return std::string(R"(gmr-marker-model 1
name chain
part base B1 B2 B3 B4
part arm j1 A1 A2
part fore F1 F2 F3
joint root in base at mean(B1, B2, B3, B4)
joint j1 parent root in base centre arm prior along(mean(B1, B2, B3, B4), B1, B2, 25mm)
)") + j2 + "joint tip parent j2 in fore at F3\n";
  };
  auto plain = parse_marker_model(model_text(""), "chain");
  ASSERT_TRUE(plain.ok()) << plain.error().to_string();
  auto p = solve_markers(s.markers, *plain);
  ASSERT_TRUE(p.ok()) << p.error().to_string();
  const std::vector<Vector3d> placed = joint_track(p->motion, "j2");
  for (std::size_t f = 0; f < placed.size(); f += 50) EXPECT_NEAR((placed[f] - s.j2[f]).norm(), 40.0, 1e-6) << f;

  // The true proportion: j1 -> j2 is 420 mm, j2 -> tip (F3) 401.1 mm.
  const double upper = 420, lower = std::hypot(30.0, 400.0);
  const double fraction = upper / (upper + lower);
  auto model = parse_marker_model(model_text(" split tip " + std::to_string(fraction)), "chain");
  ASSERT_TRUE(model.ok()) << model.error().to_string();
  const std::size_t j2_index = static_cast<std::size_t>(model->find_joint("j2"));
  EXPECT_EQ(model->joints[j2_index].split, model->find_joint("tip"));
  auto r = solve_markers(s.markers, *model);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  EXPECT_TRUE(r->warnings.empty());
  // std::to_string keeps 6 decimals: 5e-7 of the 821 mm chain.
  EXPECT_LT(max_distance(joint_track(r->motion, "j2"), s.j2), 1e-3);
  EXPECT_NEAR(r->joints[j2_index].split_shift, 40.0, 1e-3);
  EXPECT_EQ(p->joints[j2_index].split_shift, 0.0);

  // When the fore carries j2 as a point, moving j2 moves the fore's fit and
  // the tip with it: the split is repeated until it holds in the result.
  std::string coupled = model_text(" split tip 0.5");
  coupled.replace(coupled.find("part fore F1"), 12, "part fore j2 F1");
  auto c_model = parse_marker_model(coupled, "chain");
  ASSERT_TRUE(c_model.ok()) << c_model.error().to_string();
  auto c = solve_markers(s.markers, *c_model);
  ASSERT_TRUE(c.ok()) << c.error().to_string();
  EXPECT_TRUE(c->warnings.empty());
  const double up = median_distance(joint_track(c->motion, "j1"), joint_track(c->motion, "j2"));
  const double down = median_distance(joint_track(c->motion, "j2"), joint_track(c->motion, "tip"));
  std::printf("coupled split: %.4f mm + %.4f mm, fraction %.6f, moved %.3f mm\n", up, down, up / (up + down),
              c->joints[j2_index].split_shift);
  EXPECT_NEAR(up / (up + down), 0.5, 1e-4);

  // 0.9 of the chain would take j2 past half its bone: refused with a
  // warning, j2 where its markers put it.
  auto far = parse_marker_model(model_text(" split tip 0.9"), "chain");
  ASSERT_TRUE(far.ok()) << far.error().to_string();
  auto f = solve_markers(s.markers, *far);
  ASSERT_TRUE(f.ok()) << f.error().to_string();
  ASSERT_EQ(f->warnings.size(), 1u);
  EXPECT_NE(f->warnings[0].to_string().find("joint 'j2': its split (0.9 of the chain to 'tip')"), std::string::npos)
      << f->warnings[0].to_string();
  EXPECT_EQ(f->joints[j2_index].split_shift, 0.0);
  EXPECT_LT(max_distance(joint_track(f->motion, "j2"), placed), 1e-9);
}

TEST(MarkerSolve, GapsAreInterpolatedOrHeldOutliersDroppedAndMissingMarkersNamed) {
  Synthetic s = make_synthetic(false, 300);
  auto model = parse_marker_model(kChainModel, "chain");
  ASSERT_TRUE(model.ok());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  auto knock = [&](std::size_t f, std::size_t m) {
    for (int a = 0; a < 3; ++a) s.markers.positions[s.markers.index(f, m, a)] = nan;
  };
  // The fore part loses two of its three markers in frames 100-109 and at
  // the first 5 frames: interpolated 10, held 5.
  for (std::size_t f = 100; f < 110; ++f) knock(f, 6), knock(f, 7);
  for (std::size_t f = 0; f < 5; ++f) knock(f, 6), knock(f, 8);
  // A swapped base marker in frame 200: an outlier, dropped.
  for (int a = 0; a < 3; ++a) s.markers.positions[s.markers.index(200, 0, a)] += 500;
  auto r = solve_markers(s.markers, *model);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const PartFit& fore = r->parts[2];
  EXPECT_EQ(fore.interpolated, 10u);
  EXPECT_EQ(fore.held, 5u);
  EXPECT_EQ(fore.fitted, 285u);
  EXPECT_EQ(r->parts[0].outliers, 1u);
  EXPECT_LT(r->parts[0].fit_rms, 1e-6);  // the outlier is not in the fit
  EXPECT_LT(max_distance(joint_track(r->motion, "j1"), s.j1), 1e-6);

  MarkerTrajectories lacking = s.markers;
  lacking.names[4] = "Other";
  lacking.names[8] = "Else";
  auto e = solve_markers(lacking, *model);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.error().message.find("lacks 2 markers the model needs: A1, F3"), std::string::npos)
      << e.error().to_string();

  MarkerTrajectories units = s.markers;
  units.units = "deg";
  auto u = solve_markers(units, *model);
  ASSERT_FALSE(u.ok());
  EXPECT_NE(u.error().message.find("'deg' are not a length"), std::string::npos);

  auto bad_root = solve_markers(s.markers, *model, MarkerSolveOptions{{"nope"}});
  ASSERT_FALSE(bad_root.ok());
  EXPECT_NE(bad_root.error().message.find("unknown joint 'nope'"), std::string::npos);
}

// ---- CMU takes: the C3D against the AMC of the same take

struct JointError {
  std::string joint;
  double median_mm = 0;
  double p95_mm = 0;
};

struct BoneAngle {
  std::string bone;  // "lfemur": the bone from its parent joint to it
  double median_deg = 0;
  double p95_deg = 0;
  double ours_mm = 0;  // the bone's length, median over frames
  double reference_mm = 0;
};

struct TakeComparison {
  int frame_offset = 0;       // reference frame = C3D frame + frame_offset (0-based)
  double free_scale = 0;      // similarity fit's scale, mm per AMC unit
  double declared_scale = 0;  // mm per AMC unit from the ASF
  Matrix3d rotation;
  Vector3d translation;
  std::vector<JointError> errors;
  double pooled_median_mm = 0;  // over every compared joint and frame
  double pooled_p95_mm = 0;
  std::vector<BoneAngle> angles;
  MarkerSolveResult solved;
};

double quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const std::size_t i = static_cast<std::size_t>(pos);
  const double a = pos - static_cast<double>(i);
  return i + 1 < v.size() ? v[i] * (1 - a) + v[i + 1] * a : v[i];
}

// Rigid (or similarity) Kabsch of b onto a: a ~ s R b + t.
void fit_similarity(const std::vector<Vector3d>& a, const std::vector<Vector3d>& b, bool with_scale, double& s,
                    Matrix3d& r, Vector3d& t) {
  Vector3d ca = Vector3d::Zero(), cb = Vector3d::Zero();
  for (std::size_t i = 0; i < a.size(); ++i) ca += a[i], cb += b[i];
  ca /= static_cast<double>(a.size());
  cb /= static_cast<double>(b.size());
  Matrix3d h = Matrix3d::Zero();
  double var_b = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    h += (b[i] - cb) * (a[i] - ca).transpose();
    var_b += (b[i] - cb).squaredNorm();
  }
  Eigen::JacobiSVD<Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Matrix3d d = Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1 : 1;
  r = svd.matrixV() * d * svd.matrixU().transpose();
  if (with_scale) s = (svd.singularValues().asDiagonal() * d).trace() / var_b;
  t = ca - s * r * cb;
}

const std::vector<std::string> kComparedJoints = {"lhipjoint", "rhipjoint", "lfemur",    "rfemur",
                                                  "ltibia",    "rtibia",    "lclavicle", "rclavicle",
                                                  "lhumerus",  "rhumerus",  "lradius",   "rradius"};

// The bones whose directions are compared: (bone, its parent joint), in
// cmu41's names, which are the ASF's.
const std::vector<std::pair<std::string, std::string>> kComparedBones = {
    {"lfemur", "lhipjoint"},   {"rfemur", "rhipjoint"},   {"ltibia", "lfemur"},    {"rtibia", "rfemur"},
    {"lhumerus", "lclavicle"}, {"rhumerus", "rclavicle"}, {"lradius", "lhumerus"}, {"rradius", "rhumerus"}};

// What a take is compared against: a motion of the same take, its unit, and
// the name of the joint at the position each cmu41 joint names (the end of
// the ASF bone of that name).
struct Reference {
  std::string file;
  std::string asf;                           // with an AMC
  double mm_per_unit = 0;                    // 0: the unit the file declares
  std::map<std::string, std::string> names;  // cmu41 joint -> reference joint; absent: the same name
  std::optional<int> frame_offset;           // known pairing; else the best of -4..4
  std::string name_of(const std::string& ours) const {
    const auto it = names.find(ours);
    return it == names.end() ? ours : it->second;
  }
};

// CMU's BVH conversions name a joint after the bone that starts there, so
// the end of ASF bone `lfemur` (the knee) is BVH joint `LeftLeg`; they keep
// the ASF's unit (length 0.45 inch: 25.4 / 0.45 mm).
Reference cmu_bvh_reference(const std::string& file) {
  Reference r;
  r.file = file;
  r.mm_per_unit = 25.4 / 0.45;
  r.names = {{"lhipjoint", "LeftUpLeg"},   {"rhipjoint", "RightUpLeg"}, {"lfemur", "LeftLeg"},
             {"rfemur", "RightLeg"},       {"ltibia", "LeftFoot"},      {"rtibia", "RightFoot"},
             {"lclavicle", "LeftArm"},     {"rclavicle", "RightArm"},   {"lhumerus", "LeftForeArm"},
             {"rhumerus", "RightForeArm"}, {"lradius", "LeftHand"},     {"rradius", "RightHand"}};
  return r;
}

TakeComparison compare_take(const std::string& c3d, const Reference& ref) {
  TakeComparison out;
  const MarkerTrajectories markers = test::load_marker_file(c3d);
  auto model = builtin_marker_model("cmu41");
  EXPECT_TRUE(model.ok()) << (model.ok() ? "" : model.error().to_string());
  auto solved = solve_markers(markers, *model);
  EXPECT_TRUE(solved.ok()) << (solved.ok() ? "" : solved.error().to_string());
  if (!solved.ok()) return out;
  LoadOptions options;
  if (!ref.asf.empty()) options.asf = test::data_file(ref.asf);
  auto reference = load_motion(test::data_file(ref.file), options);
  EXPECT_TRUE(reference.ok()) << (reference.ok() ? "" : reference.error().to_string());
  if (!reference.ok()) return out;
  out.declared_scale =
      ref.mm_per_unit > 0 ? ref.mm_per_unit : 1000 * declared_metres_per_unit(test::data_file(ref.file), options);
  const Motion& ours = solved->motion;
  const auto ours_p = compute_positions(ours);
  const auto ref_p = compute_positions(*reference);
  std::vector<int> oj, rj;
  for (const std::string& n : kComparedJoints) {
    oj.push_back(ours.skeleton.find(n));
    rj.push_back(reference->skeleton.find(ref.name_of(n)));
    EXPECT_GE(oj.back(), 0) << n;
    EXPECT_GE(rj.back(), 0) << ref.name_of(n);
    if (oj.back() < 0 || rj.back() < 0) return out;
  }
  const std::size_t on = ours.skeleton.size(), rn = reference->skeleton.size();
  auto gather = [&](int offset, std::vector<Vector3d>& a, std::vector<Vector3d>& b) {
    a.clear();
    b.clear();
    for (std::size_t f = 0; f < ours.frame_count; ++f) {
      const long g = static_cast<long>(f) + offset;
      if (g < 0 || g >= static_cast<long>(reference->frame_count)) continue;
      for (std::size_t k = 0; k < oj.size(); ++k) {
        a.push_back(ours_p[f * on + static_cast<std::size_t>(oj[k])]);
        b.push_back(ref_p[static_cast<std::size_t>(g) * rn + static_cast<std::size_t>(rj[k])]);
      }
    }
  };
  // The frame pairing: the offset with the smallest residual after the fit.
  double best = std::numeric_limits<double>::infinity();
  std::vector<Vector3d> a, b;
  for (int offset = ref.frame_offset.value_or(-4); offset <= ref.frame_offset.value_or(4); ++offset) {
    gather(offset, a, b);
    double s = out.declared_scale;
    Matrix3d r;
    Vector3d t;
    fit_similarity(a, b, false, s, r, t);
    double sum = 0;
    for (std::size_t i = 0; i < a.size(); ++i) sum += (a[i] - (s * r * b[i] + t)).squaredNorm();
    if (sum / static_cast<double>(a.size()) < best) {
      best = sum / static_cast<double>(a.size());
      out.frame_offset = offset;
      out.rotation = r;
      out.translation = t;
    }
  }
  gather(out.frame_offset, a, b);
  Matrix3d r_free;
  Vector3d t_free;
  fit_similarity(a, b, true, out.free_scale, r_free, t_free);
  std::vector<std::vector<double>> per_joint(oj.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    per_joint[i % oj.size()].push_back((a[i] - (out.declared_scale * out.rotation * b[i] + out.translation)).norm());
  }
  std::vector<double> pooled;
  for (std::size_t k = 0; k < oj.size(); ++k) {
    out.errors.push_back({kComparedJoints[k], quantile(per_joint[k], 0.5), quantile(per_joint[k], 0.95)});
    pooled.insert(pooled.end(), per_joint[k].begin(), per_joint[k].end());
  }
  out.pooled_median_mm = quantile(pooled, 0.5);
  out.pooled_p95_mm = quantile(pooled, 0.95);
  // Bone directions (independent of bone lengths): thighs, shanks, upper
  // arms, forearms, after the same rotation.
  for (const auto& [bone, parent] : kComparedBones) {
    const int o = ours.skeleton.find(bone), op = ours.skeleton.find(parent);
    const int r = reference->skeleton.find(ref.name_of(bone)), rp = reference->skeleton.find(ref.name_of(parent));
    std::vector<double> deg, ours_mm, ref_mm;
    for (std::size_t f = 0; f < ours.frame_count; ++f) {
      const long g = static_cast<long>(f) + out.frame_offset;
      if (g < 0 || g >= static_cast<long>(reference->frame_count)) continue;
      const std::size_t gi = static_cast<std::size_t>(g);
      const Vector3d u = ours_p[f * on + static_cast<std::size_t>(o)] - ours_p[f * on + static_cast<std::size_t>(op)];
      const Vector3d v =
          out.rotation * (ref_p[gi * rn + static_cast<std::size_t>(r)] - ref_p[gi * rn + static_cast<std::size_t>(rp)]);
      deg.push_back(std::atan2(u.cross(v).norm(), u.dot(v)) * 180 / M_PI);
      ours_mm.push_back(u.norm());
      ref_mm.push_back(out.declared_scale * v.norm());
    }
    out.angles.push_back(
        {bone, quantile(deg, 0.5), quantile(deg, 0.95), quantile(ours_mm, 0.5), quantile(ref_mm, 0.5)});
  }
  out.solved = std::move(*solved);
  return out;
}

void report(const std::string& take, const TakeComparison& c) {
  std::printf("%s: reference frame = C3D frame %+d; scale %.3f mm per unit declared, %.3f fitted freely\n",
              take.c_str(), c.frame_offset, c.declared_scale, c.free_scale);
  std::printf("  %-10s %9s %9s\n", "joint", "median", "p95");
  for (const JointError& e : c.errors) std::printf("  %-10s %7.1fmm %7.1fmm\n", e.joint.c_str(), e.median_mm, e.p95_mm);
  std::printf("  %-10s %7.2fmm %7.2fmm\n", "all", c.pooled_median_mm, c.pooled_p95_mm);
  std::printf("  %-10s %9s %9s  (angle between the bone's directions) %9s %9s (length)\n", "bone", "median", "p95",
              "ours", "reference");
  for (const BoneAngle& a : c.angles) {
    std::printf("  %-10s %7.1fdeg %6.1fdeg %7.1fmm %7.1fmm\n", a.bone.c_str(), a.median_deg, a.p95_deg, a.ours_mm,
                a.reference_mm);
  }
  std::printf("  %-10s %6s %6s %6s %6s %8s %9s %9s\n", "part", "fitted", "interp", "held", "outl", "fit rms",
              "motion rms", "max");
  for (const PartFit& p : c.solved.parts) {
    std::printf("  %-10s %6zu %6zu %6zu %6zu %6.1fmm %8.1fmm %7.1fmm\n", p.name.c_str(), p.fitted, p.interpolated,
                p.held, p.outliers, p.fit_rms, p.motion_rms, p.motion_max);
  }
  std::printf("  %-10s %10s %6s %9s %9s %9s %9s\n", "joint", "functional", "det", "prior d", "split d", "fit rms",
              "bone rms");
  for (const JointFit& j : c.solved.joints) {
    std::printf("  %-10s %10s %6d %7.1fmm %7.1fmm %7.1fmm %7.1fmm\n", j.name.c_str(), j.functional ? "yes" : "no",
                j.determined, j.prior_distance, j.split_shift, j.fit_rms, j.bone_rms);
  }
}

// Every compared joint within 30 mm (median over frames) and 60 mm (95th
// percentile) of the AMC's (`max_median_mm`, `max_p95_mm` for a take whose
// AMC plays on another subject's skeleton), bone directions within 15 deg
// (median) and 20 deg (p95).
void expect_reached(const TakeComparison& c, double max_median_mm, double max_p95_mm) {
  for (const JointError& e : c.errors) {
    EXPECT_LE(e.median_mm, max_median_mm) << e.joint;
    EXPECT_LE(e.p95_mm, max_p95_mm) << e.joint;
  }
  for (const BoneAngle& a : c.angles) {
    EXPECT_LE(a.median_deg, 15.0) << a.bone;
    EXPECT_LE(a.p95_deg, 20.0) << a.bone;
  }
  // The declared unit holds: a free scale agrees within 3%.
  EXPECT_NEAR(c.free_scale / c.declared_scale, 1.0, 0.03);
  // Every part is fitted in every frame of these takes, and the motion
  // carries each part's markers within twice its fit residual plus 10 mm:
  // what making every bone constant costs down the chain (bone_rms).
  for (const PartFit& p : c.solved.parts) {
    EXPECT_EQ(p.fitted, c.solved.motion.frame_count) << p.name;
    EXPECT_LE(p.motion_rms, 2 * p.fit_rms + 10.0) << p.name;
  }
}

TEST(MarkerSolveCmu, Take01_01MatchesItsAmcJointByJoint) {
  GMR_REQUIRE_DATA();
  const TakeComparison c = compare_take("c3d/cmu_01_01.c3d", {"asfamc/01/01_01.amc", "asfamc/01/01.asf"});
  ASSERT_EQ(c.errors.size(), kComparedJoints.size());
  report("01_01", c);
  // The C3D's first frame (capture frame 40) is the AMC's frame 1.
  EXPECT_EQ(c.frame_offset, 0);
  expect_reached(c, 30.0, 60.0);
  EXPECT_LE(c.pooled_median_mm, 20.0);  // issue 37's 2 cm over all compared joints

  // The motion moved to other roots keeps every joint's position.
  const Motion& m = c.solved.motion;
  std::vector<int> roots;
  for (const char* n : {"lfemur", "thorax", "rradius"}) roots.push_back(m.skeleton.find(n));
  auto moved = set_roots(m, roots);
  ASSERT_TRUE(moved.ok()) << moved.error().to_string();
  const auto before = compute_positions(m);
  const auto after = compute_positions(*moved);
  double worst = 0;
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    for (std::size_t j = 0; j < m.skeleton.size(); ++j) {
      const int k = moved->skeleton.find(m.skeleton.joint(static_cast<int>(j)).name);
      worst = std::max(
          worst,
          (before[f * m.skeleton.size() + j] - after[f * moved->skeleton.size() + static_cast<std::size_t>(k)]).norm());
    }
  }
  EXPECT_LT(worst, 1e-9 * skeleton_size(m));
}

// 02_01 against subject 02's own skeleton (02.asf, in the corpus since
// 2026-11-27; before, the AMC was played on subject 12's, whose femur is
// 85 mm short). No constant of cmu41 was set on this take. Bounds: issue
// 37's, as for 01_01 (docs/markers.md, "Accuracy on CMU takes").
TEST(MarkerSolveCmu, Take02_01MatchesItsAmcJointByJoint) {
  GMR_REQUIRE_DATA();
  const TakeComparison c = compare_take("c3d/cmu_02_01.c3d", {"asfamc/02/02_01.amc", "asfamc/02/02.asf"});
  ASSERT_EQ(c.errors.size(), kComparedJoints.size());
  report("02_01", c);
  // The C3D's first frame (capture frame 50) is the AMC's frame 1 or 2 (the
  // pairing the residual picks).
  EXPECT_GE(c.frame_offset, 0);
  EXPECT_LE(c.frame_offset, 1);
  expect_reached(c, 30.0, 60.0);
  EXPECT_LE(c.pooled_median_mm, 20.0);
}

// The same take against subject 02's own limbs. CMU's BVH conversion of
// 02_01 (bvh/cmu/02_01.bvh: one T-pose frame, then the AMC's 343 frames)
// carries subject 02's limb bones, as 01_01.bvh carries 01.asf's (checked
// below), but not its trunk: the BVH has no `upperback` (116 mm in 01.asf),
// so its shoulders sit about 10 cm closer to the hips than any ASF's and no
// single rigid fit can bring all twelve joints within 3 cm. What subject 02's
// own skeleton does decide is asserted: every limb bone's length within
// 25 mm (measured: 0.1-18.7 mm, the left shank the longest; subject 12's
// femur is 85 mm off), and its direction as for 01_01.
TEST(MarkerSolveCmu, Take02_01MatchesSubject02sLimbsInItsBvh) {
  GMR_REQUIRE_DATA();
  // The premise, on subject 01: the BVH conversion keeps the ASF's limbs.
  {
    Reference bvh = cmu_bvh_reference("bvh/cmu/01_01.bvh");
    auto amc =
        load_motion(test::data_file("asfamc/01/01_01.amc"), LoadOptions{.asf = test::data_file("asfamc/01/01.asf")});
    auto converted = load_motion(test::data_file(bvh.file));
    ASSERT_TRUE(amc.ok() && converted.ok());
    const auto pa = compute_positions(*amc);
    const auto pb = compute_positions(*converted);
    for (const auto& [bone, parent] : kComparedBones) {
      auto length = [&](const Motion& m, const std::vector<Vector3d>& p, const std::string& x, const std::string& y) {
        return bvh.mm_per_unit *
               (p[static_cast<std::size_t>(m.skeleton.find(x))] - p[static_cast<std::size_t>(m.skeleton.find(y))])
                   .norm();
      };
      EXPECT_NEAR(length(*amc, pa, bone, parent), length(*converted, pb, bvh.name_of(bone), bvh.name_of(parent)), 0.5)
          << bone;
    }
  }
  // 02_01.bvh frame k + 1 is 02_01.amc frame k (the roots agree), and the
  // C3D's frame i is the AMC's i + 1 (Take02_01MatchesItsAmcJointByJoint).
  Reference bvh = cmu_bvh_reference("bvh/cmu/02_01.bvh");
  {
    auto amc =
        load_motion(test::data_file("asfamc/02/02_01.amc"), LoadOptions{.asf = test::data_file("asfamc/02/12.asf")});
    auto converted = load_motion(test::data_file(bvh.file));
    ASSERT_TRUE(amc.ok() && converted.ok());
    ASSERT_EQ(converted->frame_count, amc->frame_count + 1);
    const auto pa = compute_positions(*amc);
    const auto pb = compute_positions(*converted);
    const std::size_t na = amc->skeleton.size(), nb = converted->skeleton.size();
    for (std::size_t k = 0; k < amc->frame_count; ++k) {
      ASSERT_LT((pa[k * na] - pb[(k + 1) * nb]).norm(), 1e-3) << k;  // joint 0: root, Hips
    }
  }
  bvh.frame_offset = 2;
  const TakeComparison c = compare_take("c3d/cmu_02_01.c3d", bvh);
  ASSERT_EQ(c.angles.size(), kComparedBones.size());
  report("02_01 (BVH)", c);
  for (const BoneAngle& a : c.angles) {
    EXPECT_NEAR(a.ours_mm, a.reference_mm, 25.0) << a.bone;
    EXPECT_LE(a.median_deg, 15.0) << a.bone;
    EXPECT_LE(a.p95_deg, 20.0) << a.bone;
  }
}

}  // namespace
}  // namespace gmr
