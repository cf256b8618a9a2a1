// FkBlocks (server/src/fk_blocks.h): the float FK streams share, 16 frames at
// a time. Every frame it gives equals, bit for bit, what the range kernel
// computes for the block holding it, whether the block was kept, computed
// again, or computed for a frame alone; the positions agree with the double
// reference path; blocks are computed once for all readers while they fit the
// budget; a freed motion is neither kept alive nor mistaken for another.
#include "streams/fk_blocks.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/io/motion_file.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/server/view.h"
#include "test_data.h"

namespace gmr::test {
namespace {

using server::CompiledForm;
using server::FkBlocks;

std::shared_ptr<const Motion> load(const std::string& relative) {
  if (!have_data()) return nullptr;
  auto m = load_motion(data_file(relative));
  EXPECT_TRUE(m.ok()) << relative << ": " << m.error().to_string();
  if (!m.ok()) return nullptr;
  return std::make_shared<const Motion>(std::move(m).value());
}

// What the server must give for frame f: the range kernel over f's block.
struct Reference {
  std::vector<float> positions, orientations;
};
Reference reference(const fast::CompiledMotion& cm, std::size_t f, bool orientations) {
  const std::size_t n = cm.joint_count();
  const std::size_t begin = f / FkBlocks::kFrames * FkBlocks::kFrames;
  const std::size_t count = std::min(FkBlocks::kFrames, cm.frame_count() - begin);
  std::vector<float> p(count * n * 3), o(orientations ? count * n * 9 : 0), ws(fast::fk_workspace_size(cm));
  fast::FkRangeJob job{&cm, begin, begin + count, fast::Layout::kFrameMajor, 0, p, o, ws};
  EXPECT_TRUE(job.run()) << job.check().error().to_string();
  const std::size_t at = f - begin;
  Reference r;
  r.positions.assign(p.begin() + static_cast<std::ptrdiff_t>(at * n * 3),
                     p.begin() + static_cast<std::ptrdiff_t>((at + 1) * n * 3));
  if (orientations) {
    r.orientations.assign(o.begin() + static_cast<std::ptrdiff_t>(at * n * 9),
                          o.begin() + static_cast<std::ptrdiff_t>((at + 1) * n * 9));
  }
  return r;
}

bool same_bits(std::span<const float> a, std::span<const float> b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin());
}

class FkBlocksTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!have_data()) {
      if (in_ci()) FAIL() << "corpus missing at " << data_dir();
      GTEST_SKIP() << "corpus missing at " << data_dir() << " (CMU 01_01 and 02_01 BVH needed)";
    }
  }
  std::shared_ptr<const CompiledForm> form(const std::string& relative) {
    auto m = load(relative);
    if (!m) return nullptr;
    auto f = std::make_shared<const CompiledForm>(m);
    EXPECT_NE(f->get(), nullptr);
    return f;
  }
  std::vector<float> workspace(const CompiledForm& f) { return std::vector<float>(f.workspace_floats()); }
};

// Every frame of two real takes (2752 frames, and 344, whose last block holds
// 8) read in order: one block per 16 frames, each frame the range kernel's
// bits, within 1e-4 of the skeleton's size of the double reference path; read
// again, every frame comes from a kept block.
TEST_F(FkBlocksTest, EveryFrameOfRealTakesIsTheRangeKernelsAndTheReferencePositions) {
  int takes = 0;
  for (const std::string take : {"bvh/cmu/01_01.bvh", "bvh/cmu/02_01.bvh"}) {
    SCOPED_TRACE(take);
    auto f = form(take);
    ASSERT_TRUE(f && f->get());
    const fast::CompiledMotion& cm = *f->get();
    const Motion& m = *f->motion();
    const std::size_t n = cm.joint_count(), frames = cm.frame_count();
    ASSERT_EQ(frames, m.frame_count);
    FkBlocks blocks(std::size_t{64} << 20);
    auto ws = workspace(*f);
    std::vector<Eigen::Vector3d> want(n);
    std::vector<Eigen::Matrix3d> rot(n);
    const double size = skeleton_size(m);
    double worst = 0.0;
    std::size_t mismatches = 0;
    for (std::size_t fr = 0; fr < frames; ++fr) {
      const auto pose = blocks.frame(f, fr, /*orientations=*/true, ws);
      ASSERT_TRUE(pose.has_value()) << "frame " << fr;
      const Reference r = reference(cm, fr, true);
      if (!same_bits(pose->positions, r.positions) || !same_bits(pose->orientations, r.orientations)) ++mismatches;
      compute_frame(m, fr, want, rot);
      for (std::size_t j = 0; j < n; ++j) {
        const Eigen::Vector3d got(pose->positions[3 * j], pose->positions[3 * j + 1], pose->positions[3 * j + 2]);
        worst = std::max(worst, (got - want[j]).norm());
      }
    }
    EXPECT_EQ(mismatches, 0u);
    EXPECT_LT(worst, 1e-4 * size) << "largest distance from the double path";
    const std::size_t expected_blocks = (frames + FkBlocks::kFrames - 1) / FkBlocks::kFrames;
    EXPECT_EQ(blocks.blocks_computed(), expected_blocks);
    EXPECT_EQ(blocks.hits(), frames - expected_blocks);
    EXPECT_EQ(blocks.blocks(), expected_blocks);
    EXPECT_EQ(blocks.bytes(), frames * n * 12 * sizeof(float));
    // A second reader of the whole take computes nothing.
    for (std::size_t fr = frames; fr-- > 0;) ASSERT_TRUE(blocks.frame(f, fr, false, ws).has_value());
    EXPECT_EQ(blocks.blocks_computed(), expected_blocks);
    EXPECT_EQ(blocks.hits(), 2 * frames - expected_blocks);
    // Past the end: nothing, no crash.
    EXPECT_FALSE(blocks.frame(f, frames, false, ws).has_value());
    ++takes;
  }
  EXPECT_EQ(takes, 2);
}

// Streams a little apart on one motion (here 100 "streams", each 7 frames
// behind the one before, ticking together) share the blocks: each is
// computed once while the budget holds them all.
TEST_F(FkBlocksTest, StreamsOfOneMotionShareTheBlocks) {
  auto f = form("bvh/cmu/01_01.bvh");
  ASSERT_TRUE(f && f->get());
  const std::size_t frames = f->get()->frame_count();
  FkBlocks blocks(std::size_t{64} << 20);
  auto ws = workspace(*f);
  const std::size_t streams = 100, ticks = 400;
  std::size_t reads = 0, mismatches = 0;
  for (std::size_t t = 0; t < ticks; ++t) {
    for (std::size_t s = 0; s < streams; ++s) {
      const std::size_t fr = (s * 7 + t) % frames;
      const auto pose = blocks.frame(f, fr, false, ws);
      ASSERT_TRUE(pose.has_value());
      if (t % 50 == 0 && !same_bits(pose->positions, reference(*f->get(), fr, false).positions)) ++mismatches;
      ++reads;
    }
  }
  EXPECT_EQ(mismatches, 0u);
  // Frames 0 .. 99*7+399 = 1092 were read: 69 blocks, each computed once.
  EXPECT_EQ(blocks.blocks_computed(), ((streams - 1) * 7 + ticks - 1) / FkBlocks::kFrames + 1);
  EXPECT_EQ(blocks.hits(), reads - blocks.blocks_computed());
}

// A block without orientations is computed again when a reader wants them,
// and then serves both kinds; the positions are the same bits either way.
TEST_F(FkBlocksTest, OrientationsWantedLaterComputeTheBlockAgain) {
  auto f = form("bvh/cmu/02_01.bvh");
  ASSERT_TRUE(f && f->get());
  FkBlocks blocks(std::size_t{64} << 20);
  auto ws = workspace(*f);
  const auto without = blocks.frame(f, 40, false, ws);
  ASSERT_TRUE(without && without->orientations.empty());
  const std::vector<float> first(without->positions.begin(), without->positions.end());
  const auto with = blocks.frame(f, 41, true, ws);
  ASSERT_TRUE(with.has_value());
  EXPECT_EQ(blocks.blocks_computed(), 2u);
  EXPECT_EQ(blocks.blocks(), 1u);
  EXPECT_TRUE(same_bits(with->orientations, reference(*f->get(), 41, true).orientations));
  const auto again = blocks.frame(f, 40, false, ws);
  ASSERT_TRUE(again && again->orientations.empty());
  EXPECT_TRUE(same_bits(again->positions, first));
  EXPECT_EQ(blocks.blocks_computed(), 2u);
  EXPECT_EQ(blocks.hits(), 1u);
}

// Past the budget the least recently used block goes; a budget smaller than
// one block keeps nothing and still gives the right frame; budget 0 computes
// each frame alone with the one-frame kernel.
TEST_F(FkBlocksTest, TheBudgetBoundsWhatIsKept) {
  auto f = form("bvh/cmu/01_01.bvh");
  ASSERT_TRUE(f && f->get());
  const fast::CompiledMotion& cm = *f->get();
  const std::size_t block_bytes = FkBlocks::kFrames * cm.joint_count() * 3 * sizeof(float);
  auto ws = workspace(*f);

  FkBlocks two(2 * block_bytes);
  for (std::size_t fr : {0u, 16u, 32u, 0u, 48u, 16u}) {
    const auto pose = two.frame(f, fr, false, ws);
    ASSERT_TRUE(pose.has_value());
    EXPECT_TRUE(same_bits(pose->positions, reference(cm, fr, false).positions)) << "frame " << fr;
    EXPECT_LE(two.bytes(), two.budget());
  }
  // 0, 16, 32 (evicts 0), 0 again (evicts 16), 48 (evicts 32), 16 again (evicts 0).
  EXPECT_EQ(two.blocks_computed(), 6u);
  EXPECT_EQ(two.hits(), 0u);
  EXPECT_EQ(two.blocks(), 2u);
  ASSERT_TRUE(two.frame(f, 50, false, ws).has_value());  // 48's block, kept
  EXPECT_EQ(two.hits(), 1u);

  FkBlocks tiny(block_bytes / 2);
  for (std::size_t fr : {5u, 6u, 2751u}) {
    const auto pose = tiny.frame(f, fr, true, ws);
    ASSERT_TRUE(pose.has_value());
    const Reference r = reference(cm, fr, true);
    EXPECT_TRUE(same_bits(pose->positions, r.positions) && same_bits(pose->orientations, r.orientations));
  }
  EXPECT_EQ(tiny.blocks(), 0u);
  EXPECT_EQ(tiny.bytes(), 0u);
  EXPECT_EQ(tiny.blocks_computed(), 3u);

  FkBlocks none(0);
  std::vector<float> p(cm.joint_count() * 3), o(cm.joint_count() * 9);
  const auto pose = none.frame(f, 77, true, ws);
  ASSERT_TRUE(pose.has_value());
  fast::FkFrameJob job{&cm, 77, p, o, ws};
  ASSERT_TRUE(job.run());
  EXPECT_TRUE(same_bits(pose->positions, p) && same_bits(pose->orientations, o));
  EXPECT_EQ(none.frames_alone(), 1u);
  EXPECT_EQ(none.blocks_computed(), 0u);
}

// Blocks do not keep their motion alive, and a block of a freed motion is
// never read for another: a form made after the first is freed (here from
// another take, possibly at the freed one's address) gets its own frames.
TEST_F(FkBlocksTest, AFreedMotionIsNotKeptNorMistaken) {
  FkBlocks blocks(std::size_t{64} << 20);
  std::weak_ptr<const CompiledForm> gone;
  {
    auto a = form("bvh/cmu/01_01.bvh");
    ASSERT_TRUE(a && a->get());
    auto ws = workspace(*a);
    ASSERT_TRUE(blocks.frame(a, 3, true, ws).has_value());
    gone = a;
  }
  EXPECT_TRUE(gone.expired());
  int checked = 0;
  for (int round = 0; round < 8; ++round) {
    auto b = form(round % 2 == 0 ? "bvh/cmu/02_01.bvh" : "bvh/cmu/01_01.bvh");
    ASSERT_TRUE(b && b->get());
    auto ws = workspace(*b);
    const auto pose = blocks.frame(b, 3, true, ws);
    ASSERT_TRUE(pose.has_value());
    const Reference r = reference(*b->get(), 3, true);
    EXPECT_TRUE(same_bits(pose->positions, r.positions) && same_bits(pose->orientations, r.orientations));
    ++checked;
  }
  EXPECT_EQ(checked, 8);
  EXPECT_EQ(blocks.hits(), 0u);  // each form was new
}

}  // namespace
}  // namespace gmr::test
