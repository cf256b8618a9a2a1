// One take, two files: CMU 01_01 as ASF/AMC (asfamc/01) and as cgspeed's
// MotionBuilder-friendly BVH (bvh/cmu/01_01.bvh). The Acclaim model's positions
// must match the BVH's.
//
// Scale: 1. cgspeed's BVH keeps the ASF/AMC file units (the Hips channels of
// BVH frame 1 are the AMC root values rounded to 4 decimals: 9.3722 17.8693
// -17.3198; LeftUpLeg's OFFSET 1.36306 -1.79463 0.83929 is lhipjoint's
// direction x length 2.40479). For CMU, 1 unit = (1/0.45) inch = 5.644 cm
// (`units length 0.45`). Frames: the BVH has one extra first frame (a T-pose),
// so AMC frame f is BVH frame f + 1.
#include <gtest/gtest.h>

#include <map>
#include <string>

#include "acclaim_test_util.h"
#include "gmr/io/bvh.h"

namespace gmr::test {
namespace {

struct Take {
  AsfSkeleton asf;
  AmcMotion amc;
  Motion bvh;
  std::vector<Eigen::Vector3d> acclaim;      // frame-major, asf.bones.size() per frame
  std::vector<Eigen::Matrix3d> acclaim_rot;  // same layout
  std::vector<Eigen::Vector3d> bvh_pos;      // frame-major, bvh joints per frame
  std::size_t checked = 0;                   // AMC frames compared: all (fewer under the sanitizers)
};

const Take* load_take() {
  static Take take;
  static bool loaded = false;
  if (loaded) return &take;
  auto s = read_asf(data_file("asfamc/01/01.asf"));
  if (!s.ok()) return nullptr;
  auto m = read_amc(data_file("asfamc/01/01_01.amc"), *s);
  if (!m.ok()) return nullptr;
  auto b = read_bvh(data_file("bvh/cmu/01_01.bvh"));
  if (!b.ok()) return nullptr;
  take.asf = std::move(*s);
  take.amc = std::move(*m);
  take.bvh = std::move(*b);
  const std::size_t n = take.asf.bones.size();
  take.checked = frames_to_check(take.amc.frame_count);
  take.acclaim.resize(n * take.checked);
  take.acclaim_rot.resize(n * take.checked);
  for (std::size_t f = 0; f < take.checked; ++f) {
    acclaim_compute_frame(take.asf, take.amc, f, std::span(take.acclaim).subspan(f * n, n),
                          std::span(take.acclaim_rot).subspan(f * n, n));
  }
  take.bvh_pos = compute_positions(take.bvh, 0, std::min(take.checked + 1, take.bvh.frame_count));
  loaded = true;
  return &take;
}

// Bone tip (ASF) -> BVH joint at the same place.
const std::map<std::string, std::string> kLowerBody = {
    {"root", "Hips"},         {"lhipjoint", "LeftUpLeg"},   {"lfemur", "LeftLeg"},         {"ltibia", "LeftFoot"},
    {"lfoot", "LeftToeBase"}, {"ltoes", "LeftToeBase_End"}, {"rhipjoint", "RightUpLeg"},   {"rfemur", "RightLeg"},
    {"rtibia", "RightFoot"},  {"rfoot", "RightToeBase"},    {"rtoes", "RightToeBase_End"}, {"lowerback", "Spine"},
    {"upperback", "Spine1"},
};

// Upper body: same joints, but see ConstantUpperBodyDifference.
const std::map<std::string, std::string> kUpperBody = {
    {"lowerneck", "Neck1"},    {"upperneck", "Head"},        {"head", "Head_End"},
    {"lclavicle", "LeftArm"},  {"lhumerus", "LeftForeArm"},  {"lradius", "LeftHand"},
    {"rclavicle", "RightArm"}, {"rhumerus", "RightForeArm"}, {"rradius", "RightHand"},
};

TEST(LegsHipsAndLowerSpineMatchTheBvh, Cmu0101) {
  GMR_REQUIRE_DATA();
  const Take* t = load_take();
  ASSERT_NE(t, nullptr) << "could not read the 01_01 files";
  ASSERT_EQ(t->amc.frame_count, 2751u);
  ASSERT_EQ(t->bvh.frame_count, t->amc.frame_count + 1);  // the BVH's extra T-pose frame
  EXPECT_EQ(t->checked, kSanitized ? kSanitizerFrames : 2751u);
  const std::size_t n = t->asf.bones.size();
  const std::size_t nb = t->bvh.skeleton.size();
  for (const auto& [bone, joint] : kLowerBody) {
    const int b = t->asf.find(bone);
    const int j = t->bvh.skeleton.find(joint);
    ASSERT_GE(b, 0) << bone;
    ASSERT_GE(j, 0) << joint;
    double worst = 0.0;
    std::size_t worst_frame = 0;
    for (std::size_t f = 0; f < t->checked; ++f) {
      const double e =
          (t->acclaim[f * n + static_cast<std::size_t>(b)] - t->bvh_pos[(f + 1) * nb + static_cast<std::size_t>(j)])
              .norm();
      if (e > worst) worst = e, worst_frame = f;
    }
    EXPECT_LE(worst, 1e-3) << bone << " vs " << joint << ", worst at AMC frame " << worst_frame;
  }
  // The zero-offset BVH joints sit on the root.
  for (const char* z : {"LHipJoint", "RHipJoint", "LowerBack"}) {
    const int j = t->bvh.skeleton.find(z);
    ASSERT_GE(j, 0);
    for (std::size_t f = 0; f < t->checked; f += 50) {
      EXPECT_LE((t->acclaim[f * n] - t->bvh_pos[(f + 1) * nb + static_cast<std::size_t>(j)]).norm(), 1e-3) << z;
    }
  }
}

// The upper body differs by a constant: cgspeed's BVH drops the ASF's `thorax`
// bone's length (its Spine1 -> Neck and Spine1 -> LeftShoulder/RightShoulder
// offsets are 0, while the ASF's lowerneck and clavicles start at the thorax's
// tip; Spine1 still carries the thorax's rotation). So every joint above the
// thorax is off by the thorax bone, W_thorax * direction * length: a vector
// that is constant in the thorax's frame, (0.0408..., 2.0639..., 0.0483...)
// for subject 01. (The wrists' lengths are dropped the same way further down
// the arms, so the hands differ by more; they are not checked here.)
TEST(ConstantUpperBodyDifference, Cmu0101) {
  GMR_REQUIRE_DATA();
  const Take* t = load_take();
  ASSERT_NE(t, nullptr);
  const std::size_t n = t->asf.bones.size();
  const std::size_t nb = t->bvh.skeleton.size();
  const int thorax = t->asf.find("thorax");
  const AsfBone& tb = t->asf.bones[static_cast<std::size_t>(thorax)];
  const Eigen::Vector3d thorax_bone = tb.direction * tb.length;
  for (const auto& [bone, joint] : kUpperBody) {
    const int b = t->asf.find(bone);
    const int j = t->bvh.skeleton.find(joint);
    ASSERT_GE(b, 0) << bone;
    ASSERT_GE(j, 0) << joint;
    double worst_in_frame = 0.0, worst_world = 0.0;
    for (std::size_t f = 0; f < t->checked; ++f) {
      const Eigen::Vector3d d =
          t->acclaim[f * n + static_cast<std::size_t>(b)] - t->bvh_pos[(f + 1) * nb + static_cast<std::size_t>(j)];
      const Eigen::Matrix3d& w = t->acclaim_rot[f * n + static_cast<std::size_t>(thorax)];
      worst_in_frame = std::max(worst_in_frame, (w.transpose() * d - thorax_bone).norm());
      worst_world = std::max(worst_world, d.norm());
    }
    // In the thorax's frame the difference is the thorax bone, in every frame.
    EXPECT_LE(worst_in_frame, 1e-3) << bone << " vs " << joint;
    // In world axes it is as long as that bone (2.06 units), never ~0.
    EXPECT_NEAR(worst_world, tb.length, 1e-3) << bone << " vs " << joint;
  }
}

}  // namespace
}  // namespace gmr::test
