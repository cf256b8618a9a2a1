// The fast float FK path against the double reference (compute_positions), on
// generated skeletons that exercise every plan case: any channel order, position
// channels on non-roots, joints without rotation, several roots, both conventions.
#include "fast/frame_program.h"  // private: the per-joint plans
#include "gmr/fast/fast_fk.h"

#include <gtest/gtest.h>

#include <hwy/targets.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <random>
#include <vector>

#include "fast_test_util.h"
#include "gmr/kinematics/forward_kinematics.h"

namespace gmr::fast {
namespace {

using test::fast_positions;
using test::random_motion;
using test::reference_positions;

TEST(FastMatchesReference, GeneratedMotions) {
  for (int seed = 0; seed < 40; ++seed) {
    for (Convention conv : {Convention::kPostRotation, Convention::kPreRotation}) {
      const Motion m = random_motion(static_cast<unsigned>(seed), conv, 37 + seed);
      auto cm = CompiledMotion::compile(m);
      ASSERT_TRUE(cm.ok()) << cm.error().to_string();
      const double size = skeleton_size(m);
      SCOPED_TRACE("seed " + std::to_string(seed));
      EXPECT_POSITIONS_NEAR(m.skeleton, fast_positions(*cm, 0, m.frame_count), reference_positions(m), 1e-5 * size);
    }
  }
}

TEST(FastLaneTails, EveryRangeOfAShortMotion) {
  // Frame counts and ranges that are not multiples of 4, 8 or 16 lanes, and
  // ranges that start in the middle of a lane block.
  const Motion m = random_motion(7, Convention::kPostRotation, 35);
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok());
  const auto all = reference_positions(m);
  const std::size_t n = m.skeleton.size();
  for (std::size_t b = 0; b <= m.frame_count; ++b) {
    for (std::size_t e = b; e <= m.frame_count; e += 3) {
      const auto got = fast_positions(*cm, b, e);
      const std::vector<Eigen::Vector3d> want(all.begin() + static_cast<long>(b * n),
                                              all.begin() + static_cast<long>(e * n));
      SCOPED_TRACE("range " + std::to_string(b) + ":" + std::to_string(e));
      EXPECT_POSITIONS_NEAR(m.skeleton, got, want, 1e-5 * skeleton_size(m));
      EXPECT_POSITIONS_NEAR(m.skeleton, fast_positions(*cm, b, e, Layout::kJointMajor), want, 1e-5 * skeleton_size(m));
    }
  }
}

TEST(FastSingleFrame, EqualsRange) {
  for (Convention conv : {Convention::kPostRotation, Convention::kPreRotation}) {
    const Motion m = random_motion(11, conv, 21);
    auto cm = CompiledMotion::compile(m);
    ASSERT_TRUE(cm.ok());
    const std::size_t n = m.skeleton.size();
    std::vector<float> ws(fk_workspace_size(*cm));
    std::vector<float> range(m.frame_count * n * 3), range_ori(m.frame_count * n * 9);
    FkRangeJob job{.motion = &*cm,
                   .begin = 0,
                   .end = m.frame_count,
                   .out_positions = range,
                   .out_orientations = range_ori,
                   .workspace = ws};
    ASSERT_TRUE(job.run());
    std::vector<float> one(n * 3), one_ori(n * 9), scalar(n * 3);
    for (std::size_t f = 0; f < m.frame_count; ++f) {
      FkFrameJob fj{.motion = &*cm, .frame = f, .out_positions = one, .out_orientations = one_ori, .workspace = ws};
      ASSERT_TRUE(fj.run());
      ASSERT_TRUE(scalar_float_frame(*cm, f, scalar, ws));
      for (std::size_t k = 0; k < n * 3; ++k) {
        EXPECT_NEAR(one[k], range[f * n * 3 + k], 1e-4f) << "frame " << f << " value " << k;
        EXPECT_NEAR(scalar[k], range[f * n * 3 + k], 1e-4f) << "frame " << f << " value " << k;
      }
      for (std::size_t k = 0; k < n * 9; ++k) EXPECT_NEAR(one_ori[k], range_ori[f * n * 9 + k], 1e-5f);
    }
  }
}

Joint make_joint(const char* name, int parent, Eigen::Vector3d offset, std::vector<ChannelType> channels) {
  Joint j;
  j.name = name;
  j.parent = parent;
  j.offset = offset;
  j.channels = std::move(channels);
  return j;
}

// A motion of `frames` random values in [-200, 200] on these joints; joint
// `twin` gets the same three rotation channel values as joint `of` (both list
// exactly three rotation channels first).
Motion motion_with_twins(std::vector<Joint> joints, std::size_t frames, unsigned seed, int twin, int of) {
  Motion m;
  m.skeleton = Skeleton::create(std::move(joints)).value();
  m.frame_time = 1.0 / 30.0;
  m.frame_count = frames;
  m.values.resize(m.frame_count * m.stride());
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> value(-200.0, 200.0);
  for (double& v : m.values) v = value(rng);
  const auto a0 = static_cast<std::size_t>(m.skeleton.channel_offset(of));
  const auto b0 = static_cast<std::size_t>(m.skeleton.channel_offset(twin));
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    for (std::size_t i = 0; i < 3; ++i) m.values[f * m.stride() + b0 + i] = m.values[f * m.stride() + a0 + i];
  }
  return m;
}

// FkFrameJob (positions alone, and with orientations) against compute_frame
// on every frame.
void expect_frame_job_matches_reference(const Motion& m, const CompiledMotion& cm) {
  const std::size_t n = m.skeleton.size();
  std::vector<float> ws(fk_workspace_size(cm)), pos(n * 3), ori(n * 9);
  std::vector<Eigen::Vector3d> p(n);
  std::vector<Eigen::Matrix3d> w(n);
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    compute_frame(m, f, p, w);
    for (bool with_ori : {false, true}) {
      ASSERT_TRUE((FkFrameJob{.motion = &cm,
                              .frame = f,
                              .out_positions = pos,
                              .out_orientations = with_ori ? std::span<float>(ori) : std::span<float>(),
                              .workspace = ws}
                       .run()));
      for (std::size_t j = 0; j < n; ++j) {
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(pos[3 * j + static_cast<std::size_t>(a)], p[j][a], 1e-4) << j;
        if (!with_ori) continue;
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(ori[9 * j + static_cast<std::size_t>(3 * r + c)], w[j](r, c), 1e-5) << j;
        }
      }
    }
  }
}

TEST(FastSingleFrame, TwinsJointsWithoutRotationAndPositionChannels) {
  // Siblings with identical rotation channels (twins: one shared rotation),
  // joints without rotation channels, and position channels on a non-root,
  // in both conventions: FkFrameJob's per-motion program against compute_frame.
  using enum ChannelType;
  std::vector<Joint> joints;
  joints.push_back(make_joint("root", kNoParent, {1, 2, 3},
                              {kXposition, kYposition, kZposition, kZrotation, kXrotation, kYrotation}));
  joints.push_back(make_joint("a", 0, {0, 5, 0}, {kZrotation, kXrotation, kYrotation}));
  joints.push_back(make_joint("b", 0, {3, 0, 1}, {kZrotation, kXrotation, kYrotation}));  // twin of a
  joints.push_back(make_joint("c", 2, {0, 0, 4}, {kXrotation}));
  joints.push_back(make_joint("d", 2, {2, 0, 0}, {}));
  joints.push_back(make_joint("e", 1, {0, 0, 0}, {kYposition, kZrotation, kYrotation}));
  joints.push_back(make_joint("f", 5, {0, 0, 0}, {}));  // zero offset, no channels
  joints.push_back(make_joint("g", 6, {1, 1, 1}, {kXrotation, kZrotation}));
  Motion m = motion_with_twins(std::move(joints), 9, 77, /*twin=*/2, /*of=*/1);
  for (Convention conv : {Convention::kPostRotation, Convention::kPreRotation}) {
    m.convention = conv;
    auto cm = CompiledMotion::compile(m);
    ASSERT_TRUE(cm.ok()) << cm.error().to_string();
    EXPECT_EQ(cm->slot_count(), 5u);  // root, a (= b), c, e, g
    expect_frame_job_matches_reference(m, *cm);
  }
}

TEST(FastSingleFrame, RootsAndChainsWithoutRotationChannels) {
  // Roots without rotation channels (the GMR form's usual root), a joint
  // without channels between a root and a rotating joint (its position runs
  // before any rotation is computed), and a twin with a child, in both
  // conventions.
  using enum ChannelType;
  std::vector<Joint> joints;
  joints.push_back(make_joint("r1", kNoParent, {1, 2, 3}, {kXposition, kYposition, kZposition}));
  joints.push_back(make_joint("x", 0, {0, 4, 1}, {}));
  joints.push_back(make_joint("y", 1, {2, 0, 0}, {kZrotation, kXrotation}));
  joints.push_back(make_joint("z", 2, {0, 3, 0}, {}));
  joints.push_back(make_joint("w", 1, {1, 1, 0}, {}));
  joints.push_back(make_joint("r2", kNoParent, {-5, 0, 2}, {}));
  joints.push_back(make_joint("a", 5, {0, 2, 0}, {kYrotation, kXrotation, kZrotation}));
  joints.push_back(make_joint("b", 5, {1, 0, 3}, {kYrotation, kXrotation, kZrotation}));  // twin of a
  joints.push_back(make_joint("c", 7, {0, 0, 2}, {kXrotation}));
  joints.push_back(make_joint("d", 8, {1, 2, 3}, {}));
  Motion m = motion_with_twins(std::move(joints), 7, 78, /*twin=*/7, /*of=*/6);
  for (Convention conv : {Convention::kPostRotation, Convention::kPreRotation}) {
    m.convention = conv;
    auto cm = CompiledMotion::compile(m);
    ASSERT_TRUE(cm.ok()) << cm.error().to_string();
    EXPECT_EQ(cm->slot_count(), 3u);             // y, a (= b), c
    EXPECT_EQ(frame_program(*cm).prologue, 1u);  // x runs before any step
    expect_frame_job_matches_reference(m, *cm);
  }
}

TEST(FastCompile, RotationsThatAreAlwaysWholeTurnsAreNotComputed) {
  // A joint whose rotation channels are multiples of 360 degrees in every
  // frame (CMU's LHipJoint and RHipJoint are always 0) rotates by the
  // identity: it gets no world-rotation slot of its own, and positions and
  // orientations are still those of the reference.
  using enum ChannelType;
  std::vector<Joint> joints;
  joints.push_back(make_joint("root", kNoParent, {1, 2, 3},
                              {kXposition, kYposition, kZposition, kZrotation, kXrotation, kYrotation}));
  joints.push_back(make_joint("dummy", 0, {0, 5, 0}, {kZrotation, kXrotation, kYrotation}));
  joints.push_back(make_joint("b", 1, {3, 0, 1}, {kXrotation}));
  joints.push_back(make_joint("c", 2, {0, 0, 4}, {}));
  joints.push_back(make_joint("d", 1, {2, 1, 0}, {}));
  Motion m = motion_with_twins(std::move(joints), 11, 79, /*twin=*/1, /*of=*/1);
  const auto dummy = static_cast<std::size_t>(m.skeleton.channel_offset(1));
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    for (std::size_t i = 0; i < 3; ++i)
      m.values[f * m.stride() + dummy + i] = 360.0 * static_cast<double>((f + i) % 5) - 720.0;
  }
  for (Convention conv : {Convention::kPostRotation, Convention::kPreRotation}) {
    m.convention = conv;
    auto cm = CompiledMotion::compile(m);
    ASSERT_TRUE(cm.ok()) << cm.error().to_string();
    EXPECT_EQ(cm->slot_count(), 2u);  // root and b
    EXPECT_FALSE(joint_plans(*cm)[1].owns_slot);
    EXPECT_EQ(joint_plans(*cm)[1].world_slot, joint_plans(*cm)[1].parent_slot);
    expect_frame_job_matches_reference(m, *cm);
    EXPECT_POSITIONS_NEAR(m.skeleton, fast_positions(*cm, 0, m.frame_count), reference_positions(m),
                          1e-5 * skeleton_size(m));
    // Half a degree in one frame: a real rotation again.
    Motion turned = m;
    turned.values[3 * m.stride() + dummy + 1] = 0.5;
    auto ct = CompiledMotion::compile(turned);
    ASSERT_TRUE(ct.ok());
    EXPECT_EQ(ct->slot_count(), 3u);
    expect_frame_job_matches_reference(turned, *ct);
  }
}

TEST(FastSinCos, EveryAngleIsWithinFloatPrecisionOnEveryTarget) {
  // One joint rotating about Z from -720 to 720 degrees in steps of 1/64
  // (quadrant boundaries included), its child at (1, 0, 0): the child's
  // position is (cos, sin, 0) of the angle, so the positions measure the
  // kernels' sine and cosine directly, in the range and the one-frame kernel.
  using enum ChannelType;
  std::vector<Joint> joints(2);
  joints[0].name = "spin";
  joints[0].channels = {kZrotation};
  joints[1].name = "tip";
  joints[1].parent = 0;
  joints[1].offset = Eigen::Vector3d(1, 0, 0);
  Motion m;
  m.skeleton = Skeleton::create(std::move(joints)).value();
  m.frame_time = 1.0 / 30.0;
  m.frame_count = 2 * 720 * 64 + 1;
  m.values.resize(m.frame_count);
  for (std::size_t f = 0; f < m.frame_count; ++f) m.values[f] = -720.0 + static_cast<double>(f) / 64.0;
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok());
  std::vector<std::string> seen;
  for (std::int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    seen.emplace_back(simd_target_name());
    SCOPED_TRACE(seen.back());
    const auto range = fast_positions(*cm, 0, m.frame_count);
    std::vector<float> ws(fk_workspace_size(*cm)), one(6);
    double worst = 0;
    for (std::size_t f = 0; f < m.frame_count; ++f) {
      const double rad = m.values[f] * 3.14159265358979323846 / 180.0;
      ASSERT_TRUE((FkFrameJob{.motion = &*cm, .frame = f, .out_positions = one, .workspace = ws}.run()));
      const Eigen::Vector3d want(std::cos(rad), std::sin(rad), 0);
      worst = std::max({worst, (range[2 * f + 1] - want).cwiseAbs().maxCoeff(),
                        (Eigen::Vector3d(one[3], one[4], one[5]) - want).cwiseAbs().maxCoeff()});
    }
    // Float rounding of the angle itself (2^-17 degrees near 180) is 2e-8
    // radians; the polynomials add about one float ulp.
    EXPECT_LT(worst, 3e-7);
    char text[32];
    std::snprintf(text, sizeof text, "%.3g", worst);
    RecordProperty("worst_" + seen.back(), text);
  }
  hwy::SetSupportedTargetsForTest(0);
}

TEST(FastOrientations, MatchReference) {
  for (Convention conv : {Convention::kPostRotation, Convention::kPreRotation}) {
    const Motion m = random_motion(3, conv, 19);
    auto cm = CompiledMotion::compile(m);
    ASSERT_TRUE(cm.ok());
    const std::size_t n = m.skeleton.size();
    std::vector<float> ws(fk_workspace_size(*cm)), pos(m.frame_count * n * 3), ori(m.frame_count * n * 9);
    for (Layout layout : {Layout::kFrameMajor, Layout::kJointMajor}) {
      FkRangeJob job{.motion = &*cm,
                     .begin = 0,
                     .end = m.frame_count,
                     .layout = layout,
                     .out_positions = pos,
                     .out_orientations = ori,
                     .workspace = ws};
      ASSERT_TRUE(job.run());
      std::vector<Eigen::Vector3d> p(n);
      std::vector<Eigen::Matrix3d> w(n);
      for (std::size_t f = 0; f < m.frame_count; ++f) {
        compute_frame(m, f, p, w);
        for (std::size_t j = 0; j < n; ++j) {
          for (int r = 0; r < 3; ++r) {
            for (int c = 0; c < 3; ++c) {
              const std::size_t e = static_cast<std::size_t>(3 * r + c);
              const float got =
                  layout == Layout::kFrameMajor ? ori[(f * n + j) * 9 + e] : ori[(j * 9 + e) * m.frame_count + f];
              ASSERT_NEAR(got, w[j](r, c), 1e-5) << "frame " << f << " joint " << j;
            }
          }
        }
      }
    }
  }
}

TEST(FastJointMajor, MatchesFrameMajorWithStride) {
  const Motion m = random_motion(5, Convention::kPreRotation, 45);
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok());
  const std::size_t n = m.skeleton.size();
  const std::size_t b = 3, e = 40, stride = 50;
  std::vector<float> ws(fk_workspace_size(*cm)), fm((e - b) * n * 3), jm(stride * n * 3, -7.0f);
  ASSERT_TRUE((FkRangeJob{.motion = &*cm, .begin = b, .end = e, .out_positions = fm, .workspace = ws}.run()));
  ASSERT_TRUE((FkRangeJob{.motion = &*cm,
                          .begin = b,
                          .end = e,
                          .layout = Layout::kJointMajor,
                          .joint_major_stride = stride,
                          .out_positions = jm,
                          .workspace = ws}
                   .run()));
  for (std::size_t f = 0; f < e - b; ++f) {
    for (std::size_t k = 0; k < n * 3; ++k) ASSERT_EQ(fm[f * n * 3 + k], jm[k * stride + f]);
  }
  for (std::size_t k = 0; k < n * 3; ++k) {  // padding between components is left alone
    for (std::size_t f = e - b; f < stride; ++f) ASSERT_EQ(jm[k * stride + f], -7.0f);
  }
}

TEST(FastEmpty, MotionWithoutFramesOrJoints) {
  Motion m = random_motion(1, Convention::kPostRotation, 0);
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok());
  EXPECT_EQ(cm->frame_count(), 0u);
  std::vector<float> ws(fk_workspace_size(*cm));
  EXPECT_TRUE((FkRangeJob{.motion = &*cm, .begin = 0, .end = 0, .workspace = ws}.run()));
  std::vector<float> pos(m.skeleton.size() * 3);
  EXPECT_FALSE((FkFrameJob{.motion = &*cm, .frame = 0, .out_positions = pos, .workspace = ws}.run()));

  auto empty = CompiledMotion::compile(Motion{});
  ASSERT_TRUE(empty.ok());
  EXPECT_EQ(empty->joint_count(), 0u);
  std::vector<float> ws2(fk_workspace_size(*empty));
  EXPECT_TRUE((FkRangeJob{.motion = &*empty, .workspace = ws2}.run()));
}

TEST(FastJobValidity, RangeJob) {
  const Motion m = random_motion(2, Convention::kPostRotation, 20);
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok());
  const std::size_t n = m.skeleton.size();
  std::vector<float> ws(fk_workspace_size(*cm)), pos(20 * n * 3), ori(20 * n * 9);
  const FkRangeJob valid{
      .motion = &*cm, .begin = 0, .end = 20, .out_positions = pos, .out_orientations = ori, .workspace = ws};
  EXPECT_TRUE(valid.validate()) << valid.check().error().to_string();
  FkRangeJob job = valid;
  job.motion = nullptr;
  EXPECT_FALSE(job.run());
  job = valid;
  job.end = 21;
  EXPECT_FALSE(job.validate());
  job = valid;
  job.begin = 5;
  job.end = 4;
  EXPECT_FALSE(job.validate());
  job = valid;
  job.out_positions = std::span<float>(pos).first(pos.size() - 1);
  EXPECT_FALSE(job.validate());
  job = valid;
  job.out_orientations = std::span<float>(ori).first(ori.size() - 1);
  EXPECT_FALSE(job.validate());
  job = valid;
  job.workspace = std::span<float>(ws).first(ws.size() - 1);
  EXPECT_FALSE(job.validate());
  job = valid;
  job.layout = Layout::kJointMajor;
  job.joint_major_stride = 19;
  EXPECT_FALSE(job.validate());
  job.joint_major_stride = 20;
  EXPECT_TRUE(job.validate());
  job.joint_major_stride = 21;  // needs 21 * n * 3 floats
  EXPECT_FALSE(job.validate());
}

TEST(FastJobValidity, FrameJob) {
  const Motion m = random_motion(2, Convention::kPreRotation, 20);
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok());
  const std::size_t n = m.skeleton.size();
  std::vector<float> ws(fk_workspace_size(*cm)), pos(n * 3), ori(n * 9);
  const FkFrameJob valid{.motion = &*cm, .frame = 19, .out_positions = pos, .out_orientations = ori, .workspace = ws};
  EXPECT_TRUE(valid.validate());
  FkFrameJob job = valid;
  job.frame = 20;
  EXPECT_FALSE(job.run());
  job = valid;
  job.motion = nullptr;
  EXPECT_FALSE(job.validate());
  job = valid;
  job.out_positions = std::span<float>(pos).first(n * 3 - 1);
  EXPECT_FALSE(job.validate());
  job = valid;
  job.out_orientations = std::span<float>(ori).first(n * 9 - 1);
  EXPECT_FALSE(job.validate());
  job = valid;
  job.workspace = {};
  EXPECT_FALSE(job.validate());
  EXPECT_FALSE(scalar_float_frame(*cm, 20, pos, ws));
}

TEST(FastCompile, RejectsInvalidMotion) {
  Motion m = random_motion(4, Convention::kPostRotation, 10);
  m.values.pop_back();
  EXPECT_FALSE(CompiledMotion::compile(m).ok());
  m = random_motion(4, Convention::kPostRotation, 10);
  m.values[3] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(CompiledMotion::compile(m).ok());
}

TEST(FastCompile, LargeAnglesKeepPrecision) {
  // 7200.5 degrees is 0.5 degrees: reduced in double before rounding to float.
  Motion m = random_motion(9, Convention::kPostRotation, 30);
  for (std::size_t i = 0; i < m.values.size(); ++i) {
    if (i % 5 == 0) m.values[i] += 7200.0 * ((i % 3) == 0 ? -1 : 1);
  }
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok());
  EXPECT_POSITIONS_NEAR(m.skeleton, fast_positions(*cm, 0, m.frame_count), reference_positions(m),
                        1e-5 * skeleton_size(m));
}

TEST(FastAllRoots, StoredPositionsAreTheOutput) {
  // Every joint a root with position channels: the compiled form stores the
  // answer and the range job is a copy of it.
  Motion m = random_motion(6, Convention::kPreRotation, 33, /*all_roots=*/true);
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok());
  ASSERT_TRUE(cm->all_roots());
  const auto ref = reference_positions(m);
  const std::size_t joints = m.skeleton.size();
  for (std::size_t i = 0; i < ref.size(); ++i) {
    const float* frame = cm->stored_positions(i / joints);
    for (int a = 0; a < 3; ++a)
      EXPECT_EQ(frame[(i % joints) * 3 + static_cast<std::size_t>(a)], static_cast<float>(ref[i][a]));
  }
  EXPECT_POSITIONS_NEAR(m.skeleton, fast_positions(*cm, 0, m.frame_count), ref, 1e-6 * skeleton_size(m));
  EXPECT_POSITIONS_NEAR(m.skeleton, fast_positions(*cm, 5, 17, Layout::kJointMajor),
                        std::vector<Eigen::Vector3d>(ref.begin() + 5 * static_cast<long>(m.skeleton.size()),
                                                     ref.begin() + 17 * static_cast<long>(m.skeleton.size())),
                        1e-6 * skeleton_size(m));
}

TEST(FastAllRoots, AMotionWithoutChannelsStoresOneFrameForAll) {
  // 2^24 declared frames of roots without channels (a 300-byte file can say
  // so): the compiled form holds one frame, not 2^24 copies of it.
  std::vector<Joint> roots;
  for (int j = 0; j < 10; ++j) {
    Joint root;
    root.name = "r" + std::to_string(j);
    root.offset = Eigen::Vector3d(j, 2.0 * j, -j);
    roots.push_back(root);
  }
  Motion m;
  m.skeleton = Skeleton::create(std::move(roots)).value();
  m.frame_count = std::size_t{1} << 24;
  m.convention = Convention::kPreRotation;
  auto cm = CompiledMotion::compile(m);
  ASSERT_TRUE(cm.ok()) << cm.error().to_string();
  ASSERT_TRUE(cm->all_roots());
  EXPECT_LT(cm->bytes(), 4096u);
  EXPECT_EQ(cm->bytes_per_frame(), 0u);
  std::vector<float> pos(30), ws(fk_workspace_size(*cm));
  for (std::size_t f : {std::size_t{0}, m.frame_count - 1}) {
    FkFrameJob job{&*cm, f, pos, {}, ws};
    ASSERT_TRUE(job.run());
    for (int j = 0; j < 10; ++j) {
      EXPECT_EQ(pos[static_cast<std::size_t>(j) * 3 + 1], 2.0f * static_cast<float>(j));
    }
  }
  std::vector<float> range(3 * 30);
  FkRangeJob r;
  r.motion = &*cm;
  r.begin = m.frame_count - 3;
  r.end = m.frame_count;
  r.out_positions = range;
  std::vector<float> rws(fk_workspace_size(*cm));
  r.workspace = rws;
  ASSERT_TRUE(r.run());
  for (int f = 0; f < 3; ++f) EXPECT_EQ(range[static_cast<std::size_t>(f) * 30 + 9 * 3], 9.0f);
}

TEST(FastDispatch, EveryCompiledTargetMatchesReference) {
  // The dispatcher normally picks the widest target; force each one this CPU
  // runs (scalar, SSE4, AVX2, AVX-512, ...) so all of them are tested.
  std::vector<std::string> seen;
  for (std::int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    seen.emplace_back(simd_target_name());
    SCOPED_TRACE(seen.back());
    for (Convention conv : {Convention::kPostRotation, Convention::kPreRotation}) {
      const Motion m = random_motion(13, conv, 53);
      auto cm = CompiledMotion::compile(m);
      ASSERT_TRUE(cm.ok());
      EXPECT_POSITIONS_NEAR(m.skeleton, fast_positions(*cm, 1, m.frame_count),
                            std::vector<Eigen::Vector3d>(compute_positions(m, 1, m.frame_count)),
                            1e-5 * skeleton_size(m));
      // The one-frame kernel too (the scalar target falls back to the scalar chain).
      const std::size_t n = m.skeleton.size();
      std::vector<float> ws(fk_workspace_size(*cm)), one(n * 3), ori(n * 9);
      std::vector<Eigen::Vector3d> got(m.frame_count * n);
      for (std::size_t f = 0; f < m.frame_count; ++f) {
        ASSERT_TRUE(
            (FkFrameJob{.motion = &*cm, .frame = f, .out_positions = one, .out_orientations = ori, .workspace = ws}
                 .run()));
        for (std::size_t j = 0; j < n; ++j)
          got[f * n + j] = Eigen::Vector3d(one[3 * j], one[3 * j + 1], one[3 * j + 2]);
      }
      EXPECT_POSITIONS_NEAR(m.skeleton, got, compute_positions(m), 1e-5 * skeleton_size(m));
    }
  }
  hwy::SetSupportedTargetsForTest(0);
  EXPECT_FALSE(seen.empty());
  std::string all;
  for (const auto& s : seen) all += s + " ";
  RecordProperty("targets", all);
}

TEST(FastDispatch, NamesATarget) {
  EXPECT_NE(std::string(simd_target_name()), "");
  const std::size_t lanes = simd_lanes();
  EXPECT_TRUE(lanes == 1 || lanes == 4 || lanes == 8 || lanes == 16) << lanes;
}

}  // namespace
}  // namespace gmr::fast
