// Retarget requests (docs/retarget.md, "Live"): a view of a library motion or
// a live source put on the subscriber's own rig by the server. Its frames,
// queried and streamed over TCP and UDP, equal `gmr::retarget` of the same
// motion frame for frame; a re-rooted view retargets the same; a running
// subscription gets the rig's skeleton; bad rigs and maps are refused with
// the role or joint named.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <mutex>
#include <thread>

#include "gmr/io/motion_file.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/convert.h"
#include "gmr/retarget/retarget.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {
using ::testing::HasSubstr;

Motion load(const std::string& relative) {
  auto m = load_motion(data_file(relative));
  EXPECT_TRUE(m.ok()) << relative;
  return m.ok() ? std::move(m).value() : Motion{};
}

// gmr::retarget of what the server holds as cmu/02_01, in the server's form
// (pre-rotation), and its positions by joint name.
struct Expected {
  Motion motion;
  std::vector<Eigen::Vector3d> positions;  // frame-major
};
Expected expected_on(const Motion& rig) {
  auto source = to_pre_rotation(load("bvh/cmu/02_01.bvh"));
  EXPECT_TRUE(source.ok());
  auto out = retarget(*source, rig);
  EXPECT_TRUE(out.ok()) << out.error().to_string();
  auto pre = to_pre_rotation(*out);
  EXPECT_TRUE(pre.ok());
  Expected e{std::move(pre).value(), {}};
  e.positions = compute_positions(e.motion);
  return e;
}

// Positions of the view's joints (values in `joints` order) against the
// expected motion's by name: the largest difference.
double worst_difference(const Expected& e, const Skeleton& view_skeleton, const std::vector<int>& joints,
                        std::size_t frame, const std::vector<Eigen::Vector3d>& values) {
  const std::size_t n = e.motion.skeleton.size();
  double worst = 0;
  for (std::size_t k = 0; k < joints.size(); ++k) {
    const int j = e.motion.skeleton.find(view_skeleton.joint(joints[k]).name);
    if (j < 0) return INFINITY;
    worst = std::max(worst, (values[k] - e.positions[frame * n + static_cast<std::size_t>(j)]).norm());
  }
  return worst;
}

TEST(Retarget, AViewOnARigStreamsWhatGmrRetargetComputes) {
  GMR_REQUIRE_DATA();
  TestServer s;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  const Motion mixamo = load("bvh/mixamo/Beta_jump.bvh");
  const Expected want = expected_on(mixamo);
  const double tol = 1e-9 * skeleton_size(want.motion);
  for (const char* roots : {"", "LeftFoot"}) {
    SCOPED_TRACE(std::string("roots '") + roots + "'");
    auto v = c->create_view("cmu/02_01");
    ASSERT_TRUE(v.ok());
    if (*roots) {
      ASSERT_TRUE(c->set_roots(v->id, {roots}).ok());
    }
    auto on_rig = c->retarget(v->id, mixamo.skeleton);
    ASSERT_TRUE(on_rig.ok()) << on_rig.error().to_string();
    EXPECT_EQ(on_rig->skeleton.size(), mixamo.skeleton.size());
    EXPECT_GE(on_rig->skeleton.find("Beta:LeftForeArm"), 0);
    EXPECT_EQ(on_rig->frame_count, want.motion.frame_count);
    // Queried: every frame.
    auto q = c->query(v->id, 0, static_cast<std::uint32_t>(want.motion.frame_count));
    ASSERT_TRUE(q.ok()) << q.error().to_string();
    double worst = 0;
    const std::size_t n = q->joints.size();
    for (std::size_t f = 0; f < want.motion.frame_count; ++f) {
      const std::vector<Eigen::Vector3d> row(q->positions.begin() + static_cast<long>(f * n),
                                             q->positions.begin() + static_cast<long>((f + 1) * n));
      worst = std::max(worst, worst_difference(want, on_rig->skeleton, q->joints, f, row));
    }
    EXPECT_LT(worst, tol);
    // Streamed, TCP and UDP, float64.
    for (bool udp : {false, true}) {
      SCOPED_TRACE(udp ? "UDP" : "TCP");
      std::uint64_t dropped = 0;
      const auto frames = stream_all(*c, *on_rig, udp, true, false, 2000.0, &dropped);
      ASSERT_FALSE(frames.empty());
      std::vector<int> all(on_rig->skeleton.size());
      for (std::size_t j = 0; j < all.size(); ++j) all[j] = static_cast<int>(j);
      double streamed = 0;
      for (const auto& f : frames) {
        streamed = std::max(streamed, worst_difference(want, on_rig->skeleton, all, f.frame_index, f.positions));
      }
      EXPECT_LT(streamed, tol);
      if (!udp) expect_delivered_or_counted(frames.size(), dropped, want.motion.frame_count);
    }
  }
}

// A rig whose rest pose does not stand (Character Creator) with its first
// frame as the reference, and a running subscription that gets the rig.
TEST(Retarget, ARunningSubscriptionGetsTheRigAndAReferencePoseServesAFoldedRig) {
  GMR_REQUIRE_DATA();
  TestServer s;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  const Motion cc = load("bvh/cmu_iclone/001_01.bvh");
  const std::vector<double> first(cc.values.begin(), cc.values.begin() + static_cast<long>(cc.stride()));
  Motion cc_rig = cc;
  cc_rig.frame_count = 1;
  cc_rig.values = first;
  const Expected want = expected_on(cc_rig);
  auto v = c->create_view("cmu/02_01");
  ASSERT_TRUE(v.ok());
  Latch<client::SkeletonChange> changed;
  client::SubscribeOptions o;
  o.loop = true;
  o.float64 = true;
  auto sub = c->subscribe(
      v->id, o, [](const client::ReceivedFrame&) {}, {}, [&](const client::SkeletonChange& sc) { changed.set(sc); });
  ASSERT_TRUE(sub.ok()) << sub.error().to_string();
  auto without = c->retarget(v->id, cc.skeleton);
  ASSERT_FALSE(without.ok()) << "the CC rest pose is folded up";
  EXPECT_THAT(without.error().message, HasSubstr("does not stand like a humanoid"));
  auto on_rig = c->retarget(v->id, cc.skeleton, first);
  ASSERT_TRUE(on_rig.ok()) << on_rig.error().to_string();
  auto sc = changed.wait();
  ASSERT_TRUE(sc.has_value()) << "no SkeletonChanged after the retarget";
  EXPECT_EQ(sc->skeleton.size(), cc.skeleton.size());
  EXPECT_GE(sc->skeleton.find("CC_Base_L_Forearm"), 0);
  auto q = c->query(v->id, 100, 101);
  ASSERT_TRUE(q.ok());
  EXPECT_LT(worst_difference(want, on_rig->skeleton, q->joints, 100, q->positions), 1e-9 * skeleton_size(want.motion));
}

// A rig that states its unit (centimetres) on a take in inches: the view is in
// the rig's unit, so engine conventions give metres, for a query and for a
// subscription that was running in Blender's conventions before the retarget.
TEST(Retarget, ARigInItsOwnUnitComesOutInMetres) {
  GMR_REQUIRE_DATA();
  auto library = test_library();
  for (auto& e : library) {
    if (e.name == "cmu/02_01") e.metres_per_unit = 0.0254;
  }
  TestServer s({}, library);
  // What the frame callbacks touch outlives the client (declared before it).
  std::mutex mutex;
  std::vector<client::ReceivedFrame> after;
  Latch<client::SkeletonChange> changed;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  const Motion mixamo = load("bvh/mixamo/Beta_jump.bvh");
  const Expected want = expected_on(mixamo);  // in the rig's numbers
  const std::size_t n = want.motion.skeleton.size();
  auto blender = [](const Eigen::Vector3d& v) -> Eigen::Vector3d {
    return Eigen::Vector3d(v.x(), -v.z(), v.y()) * 0.01;
  };
  const double tol = 1e-9 * skeleton_size(want.motion) * 0.01;
  auto v = c->create_view("cmu/02_01");
  ASSERT_TRUE(v.ok());
  Conventions conventions;
  conventions.preset = ConventionPreset::kBlender;
  client::SubscribeOptions o;
  o.loop = true;
  o.float64 = true;
  o.conventions = conventions;
  auto sub = c->subscribe(
      v->id, o,
      [&mutex, &after, first = v->skeleton_version](const client::ReceivedFrame& f) {
        std::lock_guard lock(mutex);
        if (f.skeleton_version != first && after.size() < 40) after.push_back(f);
      },
      {}, [&](const client::SkeletonChange& sc) { changed.set(sc); });
  ASSERT_TRUE(sub.ok()) << sub.error().to_string();
  auto on_rig = c->retarget(v->id, mixamo.skeleton, {}, {}, {}, 0.01);
  ASSERT_TRUE(on_rig.ok()) << on_rig.error().to_string();
  // Queried in Blender's conventions: metres.
  client::QueryOptions qo;
  qo.conventions = conventions;
  auto q = c->query(v->id, 0, 50, qo);
  ASSERT_TRUE(q.ok()) << q.error().to_string();
  EXPECT_EQ(q->metres_per_unit, 1.0);
  double worst = 0;
  for (std::size_t f = 0; f < 50; ++f) {
    for (std::size_t k = 0; k < q->joints.size(); ++k) {
      const int j = want.motion.skeleton.find(on_rig->skeleton.joint(q->joints[k]).name);
      ASSERT_GE(j, 0);
      worst = std::max(
          worst, (q->positions[f * q->joints.size() + k] - blender(want.positions[f * n + static_cast<std::size_t>(j)]))
                     .norm());
    }
  }
  EXPECT_LT(worst, tol) << "queried positions are not the rig's centimetres in metres";
  // The running subscription: the rig's skeleton, then frames, in metres.
  auto sc = changed.wait();
  ASSERT_TRUE(sc.has_value()) << "no SkeletonChanged after the retarget";
  const int hips = sc->skeleton.find("Beta:Hips");
  ASSERT_GE(hips, 0);
  EXPECT_LT(
      (sc->rest.translations[static_cast<std::size_t>(hips)] - blender(mixamo.skeleton.joint(hips).offset)).norm(),
      tol);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(kSlowBuild ? 60 : 20);
  for (;;) {
    {
      std::lock_guard lock(mutex);
      if (after.size() >= 20) break;
    }
    ASSERT_LT(std::chrono::steady_clock::now(), deadline) << "fewer than 20 frames after the retarget";
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::lock_guard lock(mutex);
  double streamed = 0;
  for (const auto& f : after) {
    ASSERT_EQ(f.positions.size(), sc->joints.size());
    for (std::size_t k = 0; k < sc->joints.size(); ++k) {
      const int j = want.motion.skeleton.find(sc->skeleton.joint(sc->joints[k]).name);
      ASSERT_GE(j, 0);
      streamed = std::max(
          streamed, (f.positions[k] - blender(want.positions[f.frame_index * n + static_cast<std::size_t>(j)])).norm());
    }
  }
  EXPECT_LT(streamed, tol) << "streamed frames after the retarget are not in metres";
}

TEST(Retarget, BadRigsAndMapsAreRefusedNamingTheRoleOrJoint) {
  GMR_REQUIRE_DATA();
  TestServer s;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("cmu/02_01");
  ASSERT_TRUE(v.ok());
  const Motion mixamo = load("bvh/mixamo/Beta_jump.bvh");
  auto refused = [&](Result<client::ViewState> r, const std::string& says) {
    ASSERT_FALSE(r.ok());
    EXPECT_THAT(r.error().message, HasSubstr(says));
  };
  refused(c->retarget(v->id, load("bvh/truebones/Crab-dance-long.bvh").skeleton), "not a humanoid");
  refused(c->retarget(v->id, mixamo.skeleton, {}, {{"hips", "Beta:Tail"}}), "'Beta:Tail'");
  refused(c->retarget(v->id, mixamo.skeleton, {1.0, 2.0}), "the reference pose has 2 values");
  refused(c->retarget(v->id + 99, mixamo.skeleton), "view");
  refused(c->retarget(v->id, mixamo.skeleton, {}, {}, {}, -0.01), "unit (metres_per_unit)");
  refused(c->retarget(v->id, mixamo.skeleton, {}, {}, {}, std::nan("")), "unit (metres_per_unit)");
  ASSERT_TRUE(c->set_coordinates(v->id, "Head").ok());
  refused(c->retarget(v->id, mixamo.skeleton), "set world coordinates first");
  ASSERT_TRUE(c->set_coordinates(v->id, "").ok());
  // Nothing above changed the view.
  auto still = c->query(v->id, 0, 1);
  ASSERT_TRUE(still.ok());
  EXPECT_EQ(still->joints.size(), 38u);
  EXPECT_TRUE(c->retarget(v->id, mixamo.skeleton).ok());
}

}  // namespace
}  // namespace gmr::test
