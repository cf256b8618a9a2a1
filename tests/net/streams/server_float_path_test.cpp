// Float32 streams are computed by the float path (the range kernel,
// gmr::fast::FkRangeJob, on the view's compiled motion, 16 frames at a time:
// server/src/fk_blocks.h), float64 streams and queries by the double
// reference path. A float32 stream's positions equal, bit for bit after the
// float encoding, what FkRangeJob computes locally for the same view motion
// (world, intrinsic, shifted root); the server's counters say which path ran.
#include <gtest/gtest.h>

#include <algorithm>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "streams/fk_blocks.h"
#include "gmr/server/view.h"
#include "gmr/view/viewpoint.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

using client::Client;
using client::ReceivedFrame;
using client::ViewState;

// The view edits a case applies, on the server (through the client) and on a
// local server::View (the same ops on the same motion give the same motion).
struct Case {
  std::string label;
  bool shift = false;      // shift the root to the deepest joint
  bool intrinsic = false;  // see from the head (or the deepest joint's parent)
};

struct Picks {
  std::string leaf, viewer;
};
Picks pick(const Skeleton& s) {
  int leaf = 0, head = -1;
  for (int j = 0; j < static_cast<int>(s.size()); ++j) {
    if (s.depth(j) > s.depth(leaf)) leaf = j;
    if (head < 0 && (s.joint(j).name == "head" || s.joint(j).name == "Head")) head = j;
  }
  return {s.joint(leaf).name, s.joint(head >= 0 ? head : s.joint(leaf).parent).name};
}

Result<ViewState> apply(Client& c, std::uint32_t v, const Case& k, const Picks& p) {
  Result<ViewState> s = c.set_coordinates(v, "");
  if (k.shift) s = c.shift_root(v, p.leaf);
  if (!s.ok()) return s;
  if (k.intrinsic) s = c.set_coordinates(v, p.viewer);
  return s;
}

void apply(server::View& v, const Case& k, const Picks& p) {
  if (k.shift) {
    ASSERT_TRUE(v.shift_root(p.leaf).ok());
  }
  if (k.intrinsic) {
    ASSERT_TRUE(v.set_relative_to(p.viewer).ok());
  }
}

const std::vector<Case>& cases() {
  static const std::vector<Case> c = {{"world", false, false},
                                      {"intrinsic", false, true},
                                      {"shifted_root", true, false},
                                      {"shifted_and_intrinsic", true, true}};
  return c;
}

// What a float32 stream must carry for frame f: the range kernel's floats for
// f's block of 16 (the server's FkBlocks), seen from the viewer in double
// (P' = W_v^T (P - P_v)), rounded to float.
std::vector<float> expected_float_positions(const fast::CompiledMotion& cm, std::size_t f, int relative_to,
                                            std::vector<float>& ws) {
  const std::size_t n = cm.joint_count();
  const std::size_t begin = f / server::FkBlocks::kFrames * server::FkBlocks::kFrames;
  const std::size_t count = std::min(server::FkBlocks::kFrames, cm.frame_count() - begin);
  std::vector<float> block_p(count * n * 3), block_w(count * n * 9);
  fast::FkRangeJob job{&cm, begin, begin + count, fast::Layout::kFrameMajor, 0, block_p, block_w, ws};
  EXPECT_TRUE(job.run()) << job.check().error().to_string();
  const auto at = static_cast<std::ptrdiff_t>(f - begin);
  const std::vector<float> p(block_p.begin() + at * static_cast<std::ptrdiff_t>(n * 3),
                             block_p.begin() + (at + 1) * static_cast<std::ptrdiff_t>(n * 3));
  const std::vector<float> w(block_w.begin() + at * static_cast<std::ptrdiff_t>(n * 9),
                             block_w.begin() + (at + 1) * static_cast<std::ptrdiff_t>(n * 9));
  if (relative_to < 0) return p;
  std::vector<float> out(n * 3);
  const auto v = static_cast<std::size_t>(relative_to);
  for (std::size_t j = 0; j < n; ++j) {
    double d[3];
    for (std::size_t k = 0; k < 3; ++k) d[k] = static_cast<double>(p[3 * j + k]) - static_cast<double>(p[3 * v + k]);
    for (std::size_t r = 0; r < 3; ++r) {
      // (W_v^T)(r, k) = W_v(k, r), W_v row-major.
      const double x = static_cast<double>(w[9 * v + r]) * d[0] + static_cast<double>(w[9 * v + 3 + r]) * d[1] +
                       static_cast<double>(w[9 * v + 6 + r]) * d[2];
      out[3 * j + r] = static_cast<float>(x);
    }
  }
  return out;
}

// Each test streams every case's view once: the same edits on a local
// server::View (what the frames must equal) and on the server.
class FloatPath : public LibraryMotionTest {
 protected:
  struct Streamed {
    std::unique_ptr<server::View> local;
    std::vector<ReceivedFrame> frames;
    std::uint64_t dropped = 0;         // replaced while the client was not reading (counted)
    std::uint64_t computed = 0;        // frames the server computed meanwhile
    std::uint64_t computed_float = 0;  // of those, by the float path
    std::uint64_t blocks = 0;          // blocks of 16 frames the float path computed
    std::uint64_t block_hits = 0;      // frames it read from blocks already computed
  };
  Streamed stream_case(const Case& k, bool float64, bool orientations) {
    const Picks p = pick(source_->skeleton);
    Streamed out;
    out.local = std::make_unique<server::View>(0, GetParam(), source_);
    apply(*out.local, k, p);
    auto v = client_->create_view(GetParam());
    EXPECT_TRUE(v.ok()) << v.error().to_string();
    if (!v.ok()) return out;
    auto applied = apply(*client_, v->id, k, p);
    EXPECT_TRUE(applied.ok()) << applied.error().to_string();
    if (!applied.ok()) return out;
    const Skeleton& want = out.local->motion().skeleton;
    EXPECT_EQ(applied->skeleton.size(), want.size());
    for (std::size_t j = 0; j < std::min(applied->skeleton.size(), want.size()); ++j) {
      EXPECT_EQ(applied->skeleton.joint(static_cast<int>(j)).name, want.joint(static_cast<int>(j)).name);
    }
    const auto before = server_->server.stats();
    out.frames = stream_all(*client_, *applied, /*udp=*/false, float64, orientations, 2000.0, &out.dropped);
    const auto after = server_->server.stats();
    EXPECT_FALSE(out.frames.empty());
    out.computed = after.frames_computed - before.frames_computed;
    out.computed_float = after.frames_computed_float - before.frames_computed_float;
    out.blocks = after.fk_blocks_computed - before.fk_blocks_computed;
    out.block_hits = after.fk_block_hits - before.fk_block_hits;
    EXPECT_GE(out.computed, out.frames.size());
    return out;
  }
};

TEST_P(FloatPath, Float32StreamEqualsTheRangeKernelBitForBit) {
  for (const auto& k : cases()) {
    SCOPED_TRACE(k.label);
    const Streamed s = stream_case(k, /*float64=*/false, /*orientations=*/false);
    ASSERT_FALSE(s.frames.empty());
    const server::View& local = *s.local;
    const auto& frames = s.frames;
    expect_delivered_or_counted(frames.size(), s.dropped, source_->frame_count);
    // Every frame of this (only) stream ran the float path, one block of 16
    // frames computed at most for 16 of them (none when an earlier case of the
    // same motion left them kept).
    EXPECT_EQ(s.computed_float, s.computed);
    EXPECT_EQ(s.blocks + s.block_hits, s.computed_float);
    EXPECT_LE(s.blocks, (source_->frame_count + 15) / 16);
    auto cm = fast::CompiledMotion::compile(local.motion());
    ASSERT_TRUE(cm.ok()) << cm.error().to_string();
    std::vector<float> ws(fast::fk_workspace_size(*cm));

    std::size_t mismatches = 0;
    std::string first;
    for (const auto& f : frames) {
      ASSERT_LT(f.frame_index, source_->frame_count);
      ASSERT_EQ(f.positions.size(), local.motion().skeleton.size());
      const auto want = expected_float_positions(*cm, f.frame_index, local.content()->relative_to, ws);
      for (std::size_t j = 0; j < f.positions.size(); ++j) {
        for (int a = 0; a < 3; ++a) {
          const float got = static_cast<float>(f.positions[j][a]);  // exact: it was a float on the wire
          if (got != want[3 * j + static_cast<std::size_t>(a)]) {
            if (mismatches++ == 0) {
              first = "frame " + std::to_string(f.frame_index) + " joint " + std::to_string(j) + " axis " +
                      std::to_string(a) + ": got " + std::to_string(got) + ", FkRangeJob " +
                      std::to_string(want[3 * j + static_cast<std::size_t>(a)]);
            }
          }
        }
      }
    }
    EXPECT_EQ(mismatches, 0u) << "first: " << first;
  }
}

TEST_P(FloatPath, Float64StreamStillUsesTheDoublePath) {
  for (const auto& k : cases()) {
    SCOPED_TRACE(k.label);
    const Streamed s = stream_case(k, /*float64=*/true, /*orientations=*/false);
    ASSERT_FALSE(s.frames.empty());
    const server::View& local = *s.local;
    const auto& frames = s.frames;
    EXPECT_EQ(s.computed_float, 0u);
    // The double path, exactly (float64 on the wire loses nothing).
    const std::size_t n = local.motion().skeleton.size();
    std::vector<Eigen::Vector3d> want(n);
    std::vector<Eigen::Matrix3d> rot(n);
    double worst = 0.0;
    for (const auto& f : frames) {
      ASSERT_EQ(f.positions.size(), n);
      view_frame(local.motion(), local.content()->relative_to, f.frame_index, want, rot);
      for (std::size_t j = 0; j < n; ++j) worst = std::max(worst, (f.positions[j] - want[j]).norm());
    }
    EXPECT_EQ(worst, 0.0);
  }
}

TEST_P(FloatPath, Float32OrientationsMatchTheReference) {
  for (const auto& k : cases()) {
    SCOPED_TRACE(k.label);
    const Streamed s = stream_case(k, /*float64=*/false, /*orientations=*/true);
    ASSERT_FALSE(s.frames.empty());
    const server::View& local = *s.local;
    const auto& frames = s.frames;
    EXPECT_EQ(s.computed_float, s.computed);
    const std::size_t n = local.motion().skeleton.size();
    std::vector<Eigen::Vector3d> pos(n);
    std::vector<Eigen::Matrix3d> rot(n);
    double worst = 0.0, worst_pos = 0.0;
    for (const auto& f : frames) {
      ASSERT_EQ(f.orientations.size(), n);
      view_frame(local.motion(), local.content()->relative_to, f.frame_index, pos, rot);
      for (std::size_t j = 0; j < n; ++j) {
        const Eigen::Matrix3d got = f.orientations[j].normalized().toRotationMatrix();
        worst = std::max(worst, (got - rot[j]).cwiseAbs().maxCoeff());
        worst_pos = std::max(worst_pos, (f.positions[j] - pos[j]).norm());
      }
    }
    EXPECT_LT(worst, 1e-5);
    EXPECT_LT(worst_pos, 1e-6 * skeleton_size(*source_));
  }
}

INSTANTIATE_TEST_SUITE_P(Motions, FloatPath, ::testing::Values("walk", "cmu/02_01"), [](const auto& p) {
  return p.param == "walk" ? std::string("DemoWalk") : std::string("Cmu02_01");
});

// The float form follows the motion: shared by the views of one library
// motion, kept by a change of viewpoint, new after an edit; a form that
// cannot compile gives no compiled motion (streams then take the double path).
TEST(FloatPath, CompiledFormFollowsTheMotion) {
  const auto& lib = test_library();
  const auto source = std::find_if(lib.begin(), lib.end(), [](const auto& e) { return e.name == "walk"; })->motion;
  const auto shared = std::make_shared<const server::CompiledForm>(source);
  server::View a(1, "walk", source, shared);
  server::View b(2, "walk", source, shared);
  EXPECT_EQ(a.content()->compiled, shared);
  EXPECT_EQ(b.content()->compiled, shared);
  const std::string viewer = source->skeleton.joint(static_cast<int>(source->skeleton.size()) - 1).name;
  ASSERT_TRUE(a.set_relative_to(viewer).ok());
  EXPECT_EQ(a.content()->compiled, shared);  // same motion, same float form
  ASSERT_TRUE(b.shift_root(viewer).ok());
  ASSERT_NE(b.content()->compiled, nullptr);
  EXPECT_NE(b.content()->compiled, shared);  // an edited motion gets its own
  EXPECT_EQ(b.content()->compiled->motion(), b.content()->motion);
  ASSERT_NE(shared->get(), nullptr);
  EXPECT_EQ(shared->get()->joint_count(), source->skeleton.size());
  EXPECT_GT(shared->workspace_floats(), 0u);
  const server::CompiledForm none(nullptr);
  EXPECT_EQ(none.get(), nullptr);
}

}  // namespace
}  // namespace gmr::test
