// Positions a client receives (query replies, TCP streams, UDP streams) equal
// what `gmr positions` computes for the same file and view options: for world
// coordinates, shifted, split and joined roots, set roots, stripped dummies
// and the intrinsic viewpoint. Every frame of each motion is checked.
#include <gtest/gtest.h>

#include <functional>
#include <mutex>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/view/view.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

using client::Client;
using client::ReceivedFrame;
using client::ViewState;

// Picks the joints the cases operate on from the skeleton's shape.
struct Picks {
  std::string root, leaf, mid, viewer;
};
Picks pick(const Skeleton& s) {
  Picks p;
  p.root = s.joint(s.roots()[0]).name;
  int leaf = 0, mid = -1, head = -1;
  for (int j = 0; j < static_cast<int>(s.size()); ++j) {
    if (s.depth(j) > s.depth(leaf)) leaf = j;
    if (mid < 0 && s.depth(j) == 2 && !s.children(j).empty()) mid = j;
    if (head < 0 && (s.joint(j).name == "head" || s.joint(j).name == "Head")) head = j;
  }
  p.leaf = s.joint(leaf).name;
  p.mid = s.joint(mid).name;
  p.viewer = s.joint(head >= 0 ? head : s.joint(leaf).parent).name;
  return p;
}

struct Case {
  std::string label;
  // Applies the case to a server view; returns the view's new state.
  std::function<Result<ViewState>(Client&, std::uint32_t, const Picks&)> apply;
  // The same options for `gmr positions`.
  std::function<ViewSpec(const Picks&)> spec;
};

std::vector<Case> cases() {
  return {
      {"world", [](Client& c, std::uint32_t v, const Picks&) { return c.set_coordinates(v, ""); },
       [](const Picks&) { return ViewSpec{}; }},
      {"shift_root_to_leaf", [](Client& c, std::uint32_t v, const Picks& p) { return c.shift_root(v, p.leaf); },
       [](const Picks& p) {
         return ViewSpec{{p.leaf}, false, ""};
       }},
      {"split", [](Client& c, std::uint32_t v, const Picks& p) { return c.split(v, p.mid); },
       [](const Picks& p) {
         return ViewSpec{{p.root, p.mid}, false, ""};
       }},
      {"split_then_join",
       [](Client& c, std::uint32_t v, const Picks& p) -> Result<ViewState> {
         auto s = c.split(v, p.mid);
         if (!s.ok()) return s;
         return c.join(v, p.mid);
       },
       [](const Picks&) { return ViewSpec{}; }},
      {"set_roots",
       [](Client& c, std::uint32_t v, const Picks& p) {
         return c.set_roots(v, {p.leaf, p.mid});
       },
       [](const Picks& p) {
         return ViewSpec{{p.leaf, p.mid}, false, ""};
       }},
      {"strip_dummies", [](Client& c, std::uint32_t v, const Picks&) { return c.strip_dummies(v); },
       [](const Picks&) {
         return ViewSpec{{}, true, ""};
       }},
      {"intrinsic", [](Client& c, std::uint32_t v, const Picks& p) { return c.set_coordinates(v, p.viewer); },
       [](const Picks& p) {
         return ViewSpec{{}, false, p.viewer};
       }},
      {"shifted_and_intrinsic",
       [](Client& c, std::uint32_t v, const Picks& p) -> Result<ViewState> {
         auto s = c.shift_root(v, p.leaf);
         if (!s.ok()) return s;
         return c.set_coordinates(v, p.viewer);
       },
       [](const Picks& p) {
         return ViewSpec{{p.leaf}, false, p.viewer};
       }},
  };
}

// `gmr positions` for the spec: rows in the source's joint order.
struct Reference {
  std::vector<std::string> names;
  std::vector<Eigen::Vector3d> positions;  // frame-major
  Skeleton skeleton;                       // names only, for EXPECT_POSITIONS_NEAR
  double size = 1.0;
};
Reference reference(const Motion& source, const ViewSpec& spec) {
  auto v = apply_view(source, spec);
  EXPECT_TRUE(v.ok()) << v.error().to_string();
  Reference r;
  if (!v.ok()) return r;
  r.skeleton = view_names(*v);
  for (const auto& j : r.skeleton.joints()) r.names.push_back(j.name);
  r.positions = view_positions(*v, 0, v->motion.frame_count);
  r.size = skeleton_size(source);
  return r;
}

// Reorders per-view-joint values (joint indices `joints` of `view`) to the
// reference's rows, by name.
std::vector<Eigen::Vector3d> reorder(const Skeleton& view, const std::vector<int>& joints,
                                     const std::vector<Eigen::Vector3d>& values, const Reference& ref) {
  std::vector<int> column(ref.names.size(), -1);
  for (std::size_t k = 0; k < joints.size(); ++k) {
    const auto& name = view.joint(joints[k]).name;
    for (std::size_t r = 0; r < ref.names.size(); ++r) {
      if (ref.names[r] == name) column[r] = static_cast<int>(k);
    }
  }
  std::vector<Eigen::Vector3d> out;
  const std::size_t frames = joints.empty() ? 0 : values.size() / joints.size();
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t r = 0; r < ref.names.size(); ++r) {
      EXPECT_GE(column[r], 0) << "joint " << ref.names[r] << " missing from the view";
      out.push_back(column[r] >= 0 ? values[f * joints.size() + static_cast<std::size_t>(column[r])]
                                   : Eigen::Vector3d::Constant(std::nan("")));
    }
  }
  return out;
}

class ServerPositions : public LibraryMotionTest {};

TEST_P(ServerPositions, QueryEqualsGmrPositionsForEveryView) {
  const Picks p = pick(source_->skeleton);
  for (const auto& c : cases()) {
    SCOPED_TRACE(c.label);
    auto v = client_->create_view(GetParam());
    ASSERT_TRUE(v.ok()) << v.error().to_string();
    auto applied = c.apply(*client_, v->id, p);
    ASSERT_TRUE(applied.ok()) << applied.error().to_string();
    const Reference ref = reference(*source_, c.spec(p));
    auto q = client_->query(v->id, 0, static_cast<std::uint32_t>(source_->frame_count));
    ASSERT_TRUE(q.ok()) << q.error().to_string();
    EXPECT_EQ(q->skeleton_version, applied->skeleton_version);
    const auto got = reorder(applied->skeleton, q->joints, q->positions, ref);
    EXPECT_POSITIONS_NEAR(ref.skeleton, got, ref.positions, 1e-9 * ref.size);
  }
}

TEST_P(ServerPositions, TcpStreamEqualsGmrPositionsForEveryView) {
  const Picks p = pick(source_->skeleton);
  for (const auto& c : cases()) {
    SCOPED_TRACE(c.label);
    auto v = client_->create_view(GetParam());
    ASSERT_TRUE(v.ok());
    auto applied = c.apply(*client_, v->id, p);
    ASSERT_TRUE(applied.ok()) << applied.error().to_string();
    const Reference ref = reference(*source_, c.spec(p));
    std::uint64_t dropped = 0;
    const auto frames = stream_all(*client_, *applied, false, true, false, 2000.0, &dropped);
    expect_delivered_or_counted(frames.size(), dropped, source_->frame_count);
    std::vector<Eigen::Vector3d> got, want;
    std::vector<int> all(applied->skeleton.size());
    for (std::size_t j = 0; j < all.size(); ++j) all[j] = static_cast<int>(j);
    const std::size_t n = ref.names.size();
    for (std::size_t k = 0; k < frames.size(); ++k) {
      const std::size_t f = frames[k].frame_index;
      ASSERT_TRUE(k == 0 || f > frames[k - 1].frame_index);
      want.insert(want.end(), ref.positions.begin() + static_cast<std::ptrdiff_t>(f * n),
                  ref.positions.begin() + static_cast<std::ptrdiff_t>((f + 1) * n));
      EXPECT_EQ(frames[k].sequence, f);  // one frame per tick: sequence k shows frame k
      EXPECT_EQ(frames[k].view_id, v->id);
      EXPECT_EQ(frames[k].skeleton_version, applied->skeleton_version);
      EXPECT_DOUBLE_EQ(frames[k].motion_time, static_cast<double>(f) * source_->frame_time);
      EXPECT_FALSE(frames[k].udp);
      EXPECT_GT(frames[k].server_send_time_ns, 0);
      // Written after its encoding, received after it was written (one clock: loopback).
      EXPECT_GE(frames[k].server_write_time_ns, frames[k].server_send_time_ns);
      EXPECT_LE(frames[k].server_write_time_ns, frames[k].receive_time_ns);
      got.insert(got.end(), frames[k].positions.begin(), frames[k].positions.end());
    }
    EXPECT_POSITIONS_NEAR(ref.skeleton, reorder(applied->skeleton, all, got, ref), want, 1e-9 * ref.size);
  }
}

TEST_P(ServerPositions, UdpStreamEqualsGmrPositionsWithFragmentedFrames) {
  const Picks p = pick(source_->skeleton);
  for (const auto& c : cases()) {
    SCOPED_TRACE(c.label);
    auto v = client_->create_view(GetParam());
    ASSERT_TRUE(v.ok());
    auto applied = c.apply(*client_, v->id, p);
    ASSERT_TRUE(applied.ok()) << applied.error().to_string();
    const Reference ref = reference(*source_, c.spec(p));
    // float64 positions and orientations: more than one datagram per frame.
    const auto frames = stream_all(*client_, *applied, true, true, true, 1000.0);
    // UDP may lose datagrams even on loopback (a busy machine starves the
    // receiving thread): every frame that arrives must be exact, most must
    // arrive, and the server itself may have given up only a few.
    EXPECT_GE(frames.size() * 2, kSlowBuild ? 1 : source_->frame_count);
    std::vector<int> all(applied->skeleton.size());
    for (std::size_t j = 0; j < all.size(); ++j) all[j] = static_cast<int>(j);
    const std::size_t n = ref.names.size();
    for (const auto& f : frames) {
      ASSERT_TRUE(f.udp);
      ASSERT_LT(f.frame_index, source_->frame_count);
      // The write stamp ends the message, across fragments: stamped as the
      // first datagram left, between encoding and arrival.
      EXPECT_GE(f.server_write_time_ns, f.server_send_time_ns);
      EXPECT_LE(f.server_write_time_ns, f.receive_time_ns);
      EXPECT_EQ(f.orientations.size(), applied->skeleton.size());
      const auto got = reorder(applied->skeleton, all, f.positions, ref);
      const std::span<const Eigen::Vector3d> want(ref.positions.data() + f.frame_index * n, n);
      EXPECT_POSITIONS_NEAR(ref.skeleton, got, std::vector<Eigen::Vector3d>(want.begin(), want.end()), 1e-9 * ref.size);
    }
  }
  const auto counters = client_->counters();
  EXPECT_GT(counters.frames_udp, 0u);
  EXPECT_EQ(counters.udp_malformed, 0u);
  auto st = client_->stats();
  ASSERT_TRUE(st.ok());
  EXPECT_LE(st->frames_dropped * 10, source_->frame_count) << "frames the server gave up";
}

TEST_P(ServerPositions, Float32StreamIsWithinFloatPrecision) {
  auto v = client_->create_view(GetParam());
  ASSERT_TRUE(v.ok());
  const Reference ref = reference(*source_, {});
  std::uint64_t dropped = 0;
  const auto frames = stream_all(*client_, *v, false, false, false, 1000.0, &dropped);
  expect_delivered_or_counted(frames.size(), dropped, source_->frame_count);
  std::vector<Eigen::Vector3d> got, want;
  const std::size_t n = ref.names.size();
  for (const auto& f : frames) {
    got.insert(got.end(), f.positions.begin(), f.positions.end());
    want.insert(want.end(), ref.positions.begin() + static_cast<std::ptrdiff_t>(f.frame_index * n),
                ref.positions.begin() + static_cast<std::ptrdiff_t>((f.frame_index + 1) * n));
  }
  std::vector<int> all(v->skeleton.size());
  for (std::size_t j = 0; j < all.size(); ++j) all[j] = static_cast<int>(j);
  EXPECT_POSITIONS_NEAR(ref.skeleton, reorder(v->skeleton, all, got, ref), want, 1e-6 * ref.size);
}

INSTANTIATE_TEST_SUITE_P(Motions, ServerPositions, ::testing::Values("walk", "cmu/02_01"), [](const auto& p) {
  return p.param == "walk" ? std::string("DemoWalk") : std::string("Cmu02_01");
});

TEST(ServerPositions, JointSubsetAndOrientationsMatchForwardKinematics) {
  TestServer server;
  auto c = server.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("wave");
  ASSERT_TRUE(v.ok());
  const auto& lib = test_library();
  const Motion& m = *std::find_if(lib.begin(), lib.end(), [](const auto& e) { return e.name == "wave"; })->motion;
  auto q = c->query(v->id, 3, 9, true, {"head", "l_hand"});
  ASSERT_TRUE(q.ok()) << q.error().to_string();
  ASSERT_EQ(q->joints.size(), 2u);
  ASSERT_EQ(q->positions.size(), 12u);
  ASSERT_EQ(q->orientations.size(), 12u);
  std::vector<Eigen::Vector3d> p(m.skeleton.size());
  std::vector<Eigen::Matrix3d> w(m.skeleton.size());
  for (std::size_t f = 3; f < 9; ++f) {
    compute_frame(m, f, p, w);
    for (std::size_t k = 0; k < 2; ++k) {
      const int j = q->joints[k];
      EXPECT_EQ(m.skeleton.joint(j).name, k == 0 ? "head" : "l_hand");
      EXPECT_LT((q->positions[(f - 3) * 2 + k] - p[static_cast<std::size_t>(j)]).norm(), 1e-12);
      EXPECT_LT((q->orientations[(f - 3) * 2 + k].toRotationMatrix() - w[static_cast<std::size_t>(j)]).norm(), 1e-12);
    }
  }
}

}  // namespace
}  // namespace gmr::test
