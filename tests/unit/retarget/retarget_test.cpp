// Retargeting (gmr/retarget/retarget.h) on real rigs: CMU 01_01 onto the
// Character Creator rig HumanIK retargeted the same take onto (its limb
// directions against HumanIK's, frame for frame), onto Mixamo and Bandai Namco
// rigs (the rig's skeleton and bone lengths, limb directions exactly the
// source's), a round trip back to CMU, and refusals that name the role or bone.
#include "gmr/retarget/retarget.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <vector>

#include "gmr/io/motion_file.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/shift_root.h"
#include "test_data.h"

namespace gmr {
namespace {

using ::testing::HasSubstr;
using Vec = Eigen::Vector3d;

Motion load(const std::string& relative) {
  auto m = load_motion(test::data_file(relative));
  EXPECT_TRUE(m.ok()) << relative << ": " << (m.ok() ? "" : m.error().to_string());
  return m.ok() ? std::move(m).value() : Motion{};
}

// CMU 01_01 as ASF/AMC: every frame, or under the sanitizers (ten times
// slower) its first 400, which still cover its first jumps.
Motion take_01_01() {
  Motion m = load("asfamc/01/01_01.amc");
#if defined(GMR_SANITIZED)
  m.frame_count = std::min<std::size_t>(m.frame_count, 400);
  m.values.resize(m.frame_count * m.stride());
#endif
  return m;
}

double degrees_between(const Vec& a, const Vec& b) { return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI; }

double percentile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(q * static_cast<double>(v.size() - 1) + 0.5)];
}

// The limbs: (upper joint role, lower joint role), thighs to forearms.
const std::vector<std::pair<Role, Role>> kLimbBones = {
    {Role::kLeftUpperLeg, Role::kLeftLowerLeg}, {Role::kRightUpperLeg, Role::kRightLowerLeg},
    {Role::kLeftLowerLeg, Role::kLeftFoot},     {Role::kRightLowerLeg, Role::kRightFoot},
    {Role::kLeftUpperArm, Role::kLeftLowerArm}, {Role::kRightUpperArm, Role::kRightLowerArm},
    {Role::kLeftLowerArm, Role::kLeftHand},     {Role::kRightLowerArm, Role::kRightHand}};

// The output's skeleton is the rig's: names, parents and offsets.
void expect_rig_skeleton(const Skeleton& out, const Skeleton& rig) {
  ASSERT_EQ(out.size(), rig.size());
  for (int j = 0; j < static_cast<int>(rig.size()); ++j) {
    EXPECT_EQ(out.joint(j).name, rig.joint(j).name);
    EXPECT_EQ(out.joint(j).parent, rig.joint(j).parent) << rig.joint(j).name;
    EXPECT_EQ(out.joint(j).offset, rig.joint(j).offset) << rig.joint(j).name;
  }
}

// Every limb bone of `out` points where the source's does, turned by the
// plan's axes: the method's promise, checked on every frame.
double worst_limb_direction(const Motion& source, const Motion& out, const RetargetPlan& plan) {
  double worst = 0;
  std::vector<Vec> ps(source.skeleton.size()), po(out.skeleton.size());
  for (std::size_t f = 0; f < source.frame_count; ++f) {
    compute_frame(source, f, ps);
    compute_frame(out, f, po);
    for (const auto& [a, b] : kLimbBones) {
      const Vec s =
          plan.axes * (ps[static_cast<std::size_t>(plan.source[b])] - ps[static_cast<std::size_t>(plan.source[a])]);
      const Vec o = po[static_cast<std::size_t>(plan.target[b])] - po[static_cast<std::size_t>(plan.target[a])];
      worst = std::max(worst, degrees_between(s, o));
    }
  }
  return worst;
}

TEST(Humanoid, EveryHumanoidRigOfTheCorpusMapsWithItsNaming) {
  GMR_REQUIRE_DATA();
  const std::vector<std::pair<std::string, std::string>> rigs = {
      {"asfamc/01/01_01.amc", "cmu-asf"},          {"bvh/cmu/01_01.bvh", "cmu-bvh"},
      {"bvh/cmu_3dsmax/131_01.bvh", "cmu-3dsmax"}, {"bvh/cmu_daz/14_04.bvh", "daz"},
      {"bvh/mixamo/Beta_jump.bvh", "mixamo"},      {"bvh/cmu_iclone/001_01.bvh", "character-creator"},
      {"bvh/makehuman/tpose.bvh", "makehuman"}};
  std::size_t checked = 0;
  for (const auto& [file, naming] : rigs) {
    SCOPED_TRACE(file);
    const Motion m = load(file);
    auto map = map_humanoid(m.skeleton);
    ASSERT_TRUE(map.ok()) << map.error().to_string();
    EXPECT_EQ(map->naming, naming);
    ++checked;
  }
  for (const auto& file : test::data_files("bvh/bandai", ".bvh")) {
    auto m = load_motion(file);
    ASSERT_TRUE(m.ok());
    auto map = map_humanoid(m->skeleton);
    ASSERT_TRUE(map.ok()) << file << ": " << map.error().to_string();
    EXPECT_EQ(map->naming, "bandai-namco") << file;
    ++checked;
  }
  EXPECT_EQ(checked, rigs.size() + test::expected_data_files("bvh/bandai", ".bvh"));
}

// A Mixamo rig as an engine that refuses ':' in bone names has it
// (`Beta_Hips`, `mixamorig_Hips`: Godot) maps like the original, joint for
// joint; a shared prefix never hides a full name.
TEST(Humanoid, AMixamoPrefixWithAnUnderscoreMapsTheSame) {
  GMR_REQUIRE_DATA();
  const Motion m = load("bvh/mixamo/Beta_jump.bvh");
  auto original = map_humanoid(m.skeleton);
  ASSERT_TRUE(original.ok()) << original.error().to_string();
  for (const std::string prefix : {"Beta_", "mixamorig_"}) {
    SCOPED_TRACE(prefix);
    auto joints = m.skeleton.joints();
    for (auto& j : joints) j.name = prefix + j.name.substr(j.name.find(':') + 1);
    auto renamed = Skeleton::create(std::move(joints));
    ASSERT_TRUE(renamed.ok());
    auto map = map_humanoid(*renamed);
    ASSERT_TRUE(map.ok()) << map.error().to_string();
    EXPECT_EQ(map->naming, "mixamo");
    EXPECT_EQ(map->joint, original->joint);
  }
  // Not every joint shares the prefix: nothing is stripped, nothing found.
  auto joints = m.skeleton.joints();
  for (auto& j : joints) j.name = "Beta_" + j.name.substr(j.name.find(':') + 1);
  joints.back().name = "tip";
  EXPECT_FALSE(map_humanoid(*Skeleton::create(std::move(joints))).ok());
}

// CMU 01_01 (AMC) onto the Character Creator rig that HumanIK retargeted the
// same take onto: CC frame i >= 1 is AMC frame 2(i - 1) + 3 (PROVENANCE.md).
// After one global rotation fitted over every limb direction of every frame,
// the limbs agree with HumanIK's within 2 degrees median and 6 at the 95th
// percentile (per bone: docs/retarget.md).
TEST(Retarget, CmuOntoCharacterCreatorAgreesWithHumanIk) {
  GMR_REQUIRE_DATA();
  const Motion source = load("asfamc/01/01_01.amc");
  const Motion hik = load("bvh/cmu_iclone/001_01.bvh");
  RetargetPlan plan;
  auto out = retarget(source, hik, {}, &plan);
  ASSERT_TRUE(out.ok()) << out.error().to_string();
  expect_rig_skeleton(out->skeleton, hik.skeleton);
  EXPECT_EQ(out->frame_count, source.frame_count);
  EXPECT_EQ(plan.target.naming, "character-creator");
  EXPECT_EQ(plan.target_reference, "first frame") << "the CC rest pose is folded; its first frame is a T-pose";
  EXPECT_LT(worst_limb_direction(source, *out, plan), 1e-6);

  // Directions per bone and frame, ours and HumanIK's.
  std::vector<std::vector<Vec>> ours(kLimbBones.size()), theirs(kLimbBones.size());
  std::vector<Vec> po(out->skeleton.size()), ph(hik.skeleton.size());
  for (std::size_t i = 1; i < hik.frame_count && 2 * (i - 1) + 3 < out->frame_count; ++i) {
    compute_frame(*out, 2 * (i - 1) + 3, po);
    compute_frame(hik, i, ph);
    for (std::size_t b = 0; b < kLimbBones.size(); ++b) {
      const auto a = static_cast<std::size_t>(plan.target[kLimbBones[b].first]);
      const auto c = static_cast<std::size_t>(plan.target[kLimbBones[b].second]);
      ours[b].push_back((po[c] - po[a]).normalized());
      theirs[b].push_back((ph[c] - ph[a]).normalized());
    }
  }
  ASSERT_GE(ours[0].size(), 1370u);
  // The rotation R that best takes ours onto theirs (Kabsch).
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
  for (std::size_t b = 0; b < ours.size(); ++b) {
    for (std::size_t k = 0; k < ours[b].size(); ++k) h += ours[b][k] * theirs[b][k].transpose();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1 : 1;
  const Eigen::Matrix3d r = svd.matrixV() * d * svd.matrixU().transpose();
  std::vector<double> all;
  for (std::size_t b = 0; b < ours.size(); ++b) {
    std::vector<double> angles;
    for (std::size_t k = 0; k < ours[b].size(); ++k) angles.push_back(degrees_between(r * ours[b][k], theirs[b][k]));
    const double median = percentile(angles, 0.5), p95 = percentile(angles, 0.95);
    std::printf("  %-16s median %.2f deg, 95th percentile %.2f deg\n",
                std::string(role_name(kLimbBones[b].first)).c_str(), median, p95);
    EXPECT_LT(median, 3.0) << role_name(kLimbBones[b].first);
    EXPECT_LT(p95, 6.0) << role_name(kLimbBones[b].first);
    all.insert(all.end(), angles.begin(), angles.end());
  }
  std::printf("  all limbs        median %.2f deg, 95th percentile %.2f deg (%zu directions)\n", percentile(all, 0.5),
              percentile(all, 0.95), all.size());
  EXPECT_LT(percentile(all, 0.5), 2.0);
  EXPECT_LT(percentile(all, 0.95), 6.0);
}

// Onto a Mixamo rig and every Bandai Namco rig: the rig's skeleton, no NaN,
// every bone keeping its length in every frame, limbs exactly the source's.
TEST(Retarget, CmuOntoMixamoAndBandaiKeepsTheirBonesAndTheSourceLimbs) {
  GMR_REQUIRE_DATA();
  const Motion source = take_01_01();
  std::vector<std::string> rigs = {"bvh/mixamo/Beta_jump.bvh"};
  for (const auto& f : test::data_files("bvh/bandai", ".bvh")) rigs.push_back("bvh/bandai/" + f.filename().string());
  for (const auto& file : rigs) {
    SCOPED_TRACE(file);
    const Motion rig = load(file);
    RetargetPlan plan;
    auto out = retarget(source, rig, {}, &plan);
    ASSERT_TRUE(out.ok()) << out.error().to_string();
    expect_rig_skeleton(out->skeleton, rig.skeleton);
    for (double v : out->values) ASSERT_TRUE(std::isfinite(v));
    EXPECT_LT(worst_limb_direction(source, *out, plan), 1e-6);
    // Bone lengths: each joint's distance to its parent as in the rig's reference.
    std::vector<Vec> p(rig.skeleton.size()), ref(rig.skeleton.size());
    compute_frame(rig, 0, ref);
    double worst = 0;
    for (std::size_t f = 0; f < out->frame_count; f += 7) {
      compute_frame(*out, f, p);
      for (int j = 0; j < static_cast<int>(rig.skeleton.size()); ++j) {
        const int parent = rig.skeleton.joint(j).parent;
        if (parent == kNoParent) continue;
        const auto k = static_cast<std::size_t>(j), q = static_cast<std::size_t>(parent);
        worst = std::max(worst, std::abs((p[k] - p[q]).norm() - (ref[k] - ref[q]).norm()));
      }
    }
    EXPECT_LT(worst, 1e-9 * skeleton_size(rig)) << "a bone changed length by " << worst;
  }
}

// CMU -> Mixamo -> CMU (the cgspeed BVH of the same subject as the rig): every
// limb comes back pointing where it started, up to the two plans' axes.
TEST(Retarget, RoundTripThroughMixamoKeepsEveryLimb) {
  GMR_REQUIRE_DATA();
  const Motion source = take_01_01();
  RetargetPlan there, back;
  auto mixamo = retarget(source, load("bvh/mixamo/Beta_jump.bvh"), {}, &there);
  ASSERT_TRUE(mixamo.ok()) << mixamo.error().to_string();
  auto cmu = retarget(*mixamo, load("bvh/cmu/01_01.bvh"), {}, &back);
  ASSERT_TRUE(cmu.ok()) << cmu.error().to_string();
  RetargetPlan both = back;
  both.source = there.source;
  both.axes = back.axes * there.axes;
  const double worst = worst_limb_direction(source, *cmu, both);
  EXPECT_LT(worst, 1.0);
  std::printf("  round trip: limbs within %.2g deg of the source\n", worst);
}

// A re-rooted source (the legs hanging from a foot, as a view re-rooted at
// it holds them) retargets to the same frames: the method reads positions
// and the frames of bones, which a shift of the root does not change.
TEST(Retarget, AReRootedSourceRetargetsTheSame) {
  GMR_REQUIRE_DATA();
  const Motion source = take_01_01();
  const Motion rig = load("bvh/mixamo/Beta_jump.bvh");
  auto plain = retarget(source, rig);
  ASSERT_TRUE(plain.ok()) << plain.error().to_string();
  for (const char* joint : {"ltibia", "head", "rhand"}) {
    SCOPED_TRACE(joint);
    auto rerooted = shift_root(source, source.skeleton.find(joint));
    ASSERT_TRUE(rerooted.ok()) << rerooted.error().to_string();
    auto out = retarget(*rerooted, rig);
    ASSERT_TRUE(out.ok()) << out.error().to_string();
    const auto a = compute_positions(*plain), b = compute_positions(*out);
    ASSERT_EQ(a.size(), b.size());
    double worst = 0;
    for (std::size_t k = 0; k < a.size(); ++k) worst = std::max(worst, (a[k] - b[k]).norm());
    EXPECT_LT(worst, 1e-9 * skeleton_size(*plain)) << "frames differ by " << worst;
  }
}

// Refusals name what is wrong: a map with an absent bone, a bone given two
// roles, a role that does not exist, a rig that is no humanoid, one joint.
TEST(Retarget, BadMapsAndRigsAreRefusedNamingTheRoleOrBone) {
  GMR_REQUIRE_DATA();
  const Motion source = take_01_01();
  const Motion rig = load("bvh/mixamo/Beta_jump.bvh");
  auto mapped = map_humanoid(rig.skeleton);
  ASSERT_TRUE(mapped.ok());
  std::map<std::string, std::string> map;
  for (std::size_t r = 0; r < kRoleCount; ++r) {
    if (mapped->joint[r] >= 0)
      map[std::string(role_name(static_cast<Role>(r)))] = rig.skeleton.joint(mapped->joint[r]).name;
  }
  auto refused = [&](std::map<std::string, std::string> m, const Motion& target) {
    RetargetOptions o;
    o.target_map = &m;
    auto r = retarget(source, target, o);
    EXPECT_FALSE(r.ok());
    return r.ok() ? std::string() : r.error().message;
  };
  {
    RetargetOptions o;
    o.target_map = &map;
    EXPECT_TRUE(retarget(source, rig, o).ok()) << "the map the built-in naming finds, given back";
  }
  auto absent = map;
  absent["left_hand"] = "Beta:LeftPaw";
  EXPECT_THAT(refused(absent, rig), HasSubstr("'Beta:LeftPaw'"));
  auto twice = map;
  twice["right_hand"] = map["left_hand"];
  EXPECT_THAT(refused(twice, rig), HasSubstr("two roles: left_hand and right_hand"));
  auto unknown = map;
  unknown["tail"] = "Beta:Hips";
  EXPECT_THAT(refused(unknown, rig), HasSubstr("unknown role 'tail'"));
  auto missing = map;
  missing.erase("left_foot");
  EXPECT_THAT(refused(missing, rig), HasSubstr("left_foot"));
  auto crossed = map;
  std::swap(crossed["left_lower_arm"], crossed["left_lower_leg"]);
  EXPECT_THAT(refused(crossed, rig), HasSubstr("is not below"));

  auto crab = retarget(source, load("bvh/truebones/Crab-dance-long.bvh"));
  ASSERT_FALSE(crab.ok());
  EXPECT_THAT(crab.error().message, HasSubstr("not a humanoid"));
  Motion one;
  Joint j;
  j.name = "only";
  j.channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
  one.skeleton = Skeleton::create({j}).value();
  auto lone = retarget(source, one);
  ASSERT_FALSE(lone.ok());
  EXPECT_THAT(lone.error().message, HasSubstr("not a humanoid"));
  auto backwards = retarget(one, rig);
  ASSERT_FALSE(backwards.ok());
  EXPECT_THAT(backwards.error().message, HasSubstr("the source"));
}

}  // namespace
}  // namespace gmr
