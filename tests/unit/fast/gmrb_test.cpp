// The .gmrb binary format: exact round trips, and clear errors (never a crash
// or an unbounded allocation) for truncated and corrupt files.
#include "gmr/io/gmrb.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>

#include "fast_test_util.h"
#include "gmr/ops/convert.h"
#include "gmr/io/bvh.h"
#include "gmr/core/file_util.h"
#include "gmr/io/motion_file.h"

namespace gmr {
namespace {

namespace fs = std::filesystem;
using fast::test::random_motion;

void expect_identical(const Motion& a, const Motion& b) {
  ASSERT_EQ(a.skeleton.size(), b.skeleton.size());
  for (std::size_t j = 0; j < a.skeleton.size(); ++j) {
    const Joint& x = a.skeleton.joint(static_cast<int>(j));
    const Joint& y = b.skeleton.joint(static_cast<int>(j));
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.parent, y.parent);
    EXPECT_EQ(x.soft_parent, y.soft_parent);
    EXPECT_EQ(x.channels, y.channels);
    EXPECT_EQ(std::memcmp(x.offset.data(), y.offset.data(), sizeof(double) * 3), 0) << x.name;
  }
  EXPECT_EQ(a.convention, b.convention);
  EXPECT_EQ(a.frame_count, b.frame_count);
  EXPECT_EQ(std::memcmp(&a.frame_time, &b.frame_time, sizeof(double)), 0);
  ASSERT_EQ(a.values.size(), b.values.size());
  if (!a.values.empty()) {
    EXPECT_EQ(std::memcmp(a.values.data(), b.values.data(), a.values.size() * sizeof(double)), 0);
  }
}

using test::TempDir;

Motion small_motion() {
  Motion m = random_motion(21, Convention::kPreRotation, 5);
  // A soft link and a subnormal, a negative zero and a huge value: bits survive.
  std::vector<Joint> joints = m.skeleton.joints();
  joints[7].soft_parent = 3;
  m.skeleton = Skeleton::create(joints).value();
  m.values[0] = -0.0;
  m.values[1] = std::numeric_limits<double>::denorm_min();
  m.values[2] = 1e300;
  m.frame_time = 1.0 / 120.0;
  return m;
}

TEST(GmrbRoundTrip, GeneratedMotionsInMemory) {
  for (Convention conv : {Convention::kPreRotation, Convention::kPostRotation}) {
    for (std::size_t frames : {0u, 1u, 17u}) {
      const Motion m = random_motion(3, conv, frames);
      auto bytes = format_gmrb(m);
      ASSERT_TRUE(bytes.ok());
      auto back = parse_gmrb(*bytes, "<memory>");
      ASSERT_TRUE(back.ok()) << back.error().to_string();
      expect_identical(m, *back);
    }
  }
  const Motion m = small_motion();
  auto back = parse_gmrb(format_gmrb(m).value(), "<memory>");
  ASSERT_TRUE(back.ok()) << back.error().to_string();
  expect_identical(m, *back);
  EXPECT_EQ(format_gmrb(Motion{}).value().size(), 64u);  // empty motion: header only
  EXPECT_TRUE(parse_gmrb(format_gmrb(Motion{}).value(), "<memory>").ok());
}

TEST(GmrbRoundTrip, EveryBvhThroughFiles) {
  GMR_REQUIRE_DATA();
  TempDir dir;
  for (const auto& path : test::data_files("bvh", ".bvh")) {
    SCOPED_TRACE(path.string());
    auto bvh = read_bvh(path);
    ASSERT_TRUE(bvh.ok()) << bvh.error().to_string();
    auto gmr = to_pre_rotation(*bvh);
    ASSERT_TRUE(gmr.ok());
    // write_gmrb/read_gmrb, and save_motion/load_motion by extension (which
    // converts the BVH to GMR on the way).
    const fs::path a = dir.path / "a.gmrb";
    const fs::path b = dir.path / "b.GMRB";
    ASSERT_TRUE(write_gmrb(*gmr, a).ok());
    ASSERT_TRUE(save_motion(*bvh, b).ok());
    auto ra = read_gmrb(a);
    ASSERT_TRUE(ra.ok()) << ra.error().to_string();
    expect_identical(*gmr, *ra);
    auto rb = load_motion(b);
    ASSERT_TRUE(rb.ok()) << rb.error().to_string();
    expect_identical(*gmr, *rb);
    // The file holds exactly header + skeleton + 8 bytes per value.
    EXPECT_GE(fs::file_size(a), 64 + gmr->values.size() * 8);
    EXPECT_LT(fs::file_size(a), 64 + 64 + gmr->values.size() * 8 + gmr->skeleton.size() * (4 + 64 + 8 + 24 + 7));
  }
}

TEST(GmrbCorrupt, EveryTruncationIsAnError) {
  const std::string bytes = format_gmrb(small_motion()).value();
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    auto r = parse_gmrb(std::string_view(bytes).substr(0, n), "cut.gmrb");
    ASSERT_FALSE(r.ok()) << "prefix of " << n << " bytes parsed";
    EXPECT_EQ(r.error().file, "cut.gmrb");
    EXPECT_NE(r.error().message.find("at byte"), std::string::npos) << r.error().message;
  }
  // And through a real file.
  TempDir dir;
  const fs::path p = dir.path / "cut.gmrb";
  ASSERT_TRUE(write_file_atomic(p, std::string_view(bytes).substr(0, bytes.size() - 3)).ok());
  auto r = read_gmrb(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().to_string().find("cut.gmrb"), std::string::npos);
  EXPECT_NE(r.error().message.find("truncated"), std::string::npos) << r.error().message;
}

TEST(GmrbCorrupt, EveryBitFlipInHeaderAndSkeletonIsHandled) {
  // Each flip either gives an error or a motion that validates; none crashes
  // (the sanitizer build runs this too).
  const std::string bytes = format_gmrb(small_motion()).value();
  std::size_t errors = 0;
  const std::size_t data_offset = bytes.size() - small_motion().values.size() * 8;
  for (std::size_t i = 0; i < data_offset; ++i) {
    for (int bit = 0; bit < 8; ++bit) {
      std::string b = bytes;
      b[i] = static_cast<char>(b[i] ^ (1 << bit));
      auto r = parse_gmrb(b, "flip.gmrb");
      if (!r.ok()) {
        ++errors;
        EXPECT_FALSE(r.error().message.empty());
      } else {
        EXPECT_TRUE(r->validate().ok());
      }
    }
  }
  EXPECT_GT(errors, data_offset);  // most flips are caught
}

// Overwrites `size` bytes at `offset` with the little-endian `value`.
template <class T>
std::string patched(std::string bytes, std::size_t offset, T value) {
  std::memcpy(bytes.data() + offset, &value, sizeof value);
  return bytes;
}

void expect_error(const std::string& bytes, const std::string& needle) {
  auto r = parse_gmrb(bytes, "bad.gmrb");
  ASSERT_FALSE(r.ok()) << "expected an error containing '" << needle << "'";
  EXPECT_NE(r.error().message.find(needle), std::string::npos) << r.error().to_string();
}

TEST(GmrbCorrupt, HeaderFieldsAreChecked) {
  const std::string good = format_gmrb(small_motion()).value();
  expect_error("BVH\nHIERARCHY\n" + std::string(64, ' '), "bad magic");
  expect_error(patched(good, 8, std::uint32_t{2}), "version 2");
  expect_error(patched(good, 12, std::uint32_t{0x04030201}), "byte-order mark");
  expect_error(patched(good, 16, std::uint32_t{128}), "header size");
  expect_error(patched(good, 20, std::uint32_t{7}), "convention");
  expect_error(patched(good, 24, std::uint64_t{1} << 60), "joints cannot fit");
  expect_error(patched(good, 32, std::uint64_t{1} << 60), "channels for");
  // A frame count far beyond the data is rejected before allocating.
  expect_error(patched(good, 40, std::uint64_t{1} << 58), "truncated or corrupt");
  expect_error(patched(good, 40, std::uint64_t{4}), "truncated or corrupt");
  expect_error(patched(good, 48, std::numeric_limits<double>::quiet_NaN()), "frame time");
  expect_error(patched(good, 48, -1.0), "frame time");
  expect_error(patched(good, 56, std::uint64_t{1} << 62), "only");
  expect_error(good + std::string(8, '\0'), "truncated or corrupt");  // trailing bytes
}

TEST(GmrbCorrupt, SkeletonAndValuesAreChecked) {
  const Motion m = small_motion();
  const std::string good = format_gmrb(m).value();
  // Joint 0's record starts at byte 64: name length, name, parent, ...
  expect_error(patched(good, 64, std::uint32_t{0}), "name length 0");
  expect_error(patched(good, 64, std::uint32_t{1} << 20), "name length");
  const std::size_t parent_at = 64 + 4 + m.skeleton.joint(0).name.size();
  expect_error(patched(good, parent_at, std::int32_t{5}), "invalid skeleton");
  const std::size_t offset_at = parent_at + 8;
  expect_error(patched(good, offset_at, std::numeric_limits<double>::infinity()), "offset is not finite");
  const std::size_t count_at = offset_at + 24;
  expect_error(patched(good, count_at, std::uint8_t{9}), "at most 6");
  expect_error(patched(good, count_at + 1, std::uint8_t{6}), "unknown channel code");
  const std::size_t data_at = good.size() - m.values.size() * 8;
  expect_error(patched(good, data_at + 8 * 3, std::numeric_limits<double>::quiet_NaN()),
               "value 3 of frame 0 is not finite");
}

TEST(GmrbCorrupt, NonFiniteValuesAreFoundInAnyBlockAndExtremeFiniteValuesPass) {
  // 2000 frames of a 14-joint motion: the check runs in blocks of 4096
  // values, and the bad values below land in the first, the second, a middle
  // and the last block.
  Motion m = random_motion(4, Convention::kPostRotation, 2000);
  const std::size_t n = m.values.size();
  ASSERT_GT(n, 2 * 4096u);
  m.values[0] = std::numeric_limits<double>::max();
  m.values[1] = -std::numeric_limits<double>::max();
  m.values[2] = std::numeric_limits<double>::denorm_min();
  m.values[3] = -0.0;
  m.values[n - 1] = -std::numeric_limits<double>::max();
  const std::string good = format_gmrb(m).value();
  auto ok = parse_gmrb(good, "x.gmrb");
  ASSERT_TRUE(ok.ok()) << ok.error().to_string();
  expect_identical(m, *ok);
  const std::size_t data_at = good.size() - n * 8;
  for (const std::size_t i : {std::size_t{5}, std::size_t{4096}, n / 2 + 3, n - 1}) {
    for (const double bad : {std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity(),
                             std::numeric_limits<double>::quiet_NaN()}) {
      SCOPED_TRACE(i);
      const std::string want =
          "value " + std::to_string(i % m.stride()) + " of frame " + std::to_string(i / m.stride()) + " is not finite";
      expect_error(patched(good, data_at + 8 * i, bad), want);
    }
  }
}

// A recording written frame by frame is the file write_gmrb makes of the
// whole motion, byte for byte; until finish() nothing is at the path, and
// an appender dropped unfinished leaves nothing behind (not its temporary).
TEST(GmrbAppend, FrameByFrameIsTheWholeFileAndAtomic) {
  TempDir dir;
  const Motion m = small_motion();
  const fs::path whole = dir.path / "whole.gmrb", appended = dir.path / "appended.gmrb";
  ASSERT_TRUE(write_gmrb(m, whole));
  {
    auto a = GmrbAppender::open(m, appended);
    ASSERT_TRUE(a) << a.error().to_string();
    const std::size_t stride = m.stride();
    for (std::size_t f = 0; f < m.frame_count; ++f) {
      ASSERT_TRUE(a->append(std::span<const double>(m.values).subspan(f * stride, stride)));
      EXPECT_FALSE(fs::exists(appended)) << "in place before finish()";
    }
    EXPECT_FALSE(a->append(std::span<const double>(m.values).subspan(0, stride - 1)))
        << "a frame of the wrong size is refused";
    auto size = a->finish();
    ASSERT_TRUE(size) << size.error().to_string();
    EXPECT_EQ(*size, fs::file_size(appended));
  }
  EXPECT_EQ(read_file(whole).value(), read_file(appended).value());
  expect_identical(m, read_gmrb(appended).value());
  // Large enough to pass the write buffer several times.
  Motion big = random_motion(40, Convention::kPreRotation, 3000);
  {
    auto a = GmrbAppender::open(big, dir.path / "big.gmrb");
    ASSERT_TRUE(a);
    for (std::size_t f = 0; f < big.frame_count; ++f) {
      ASSERT_TRUE(a->append(std::span<const double>(big.values).subspan(f * big.stride(), big.stride())));
    }
    ASSERT_TRUE(a->finish());
  }
  expect_identical(big, read_gmrb(dir.path / "big.gmrb").value());
  {
    auto a = GmrbAppender::open(m, dir.path / "dropped.gmrb");
    ASSERT_TRUE(a);
    ASSERT_TRUE(a->append(std::span<const double>(m.values).subspan(0, m.stride())));
  }
  std::size_t files = 0;
  for (const auto& e : fs::directory_iterator(dir.path)) {
    ++files;
    EXPECT_NE(e.path().filename(), "dropped.gmrb");
  }
  EXPECT_EQ(files, 3u) << "whole, appended and big only";
}

TEST(GmrbErrors, MissingFileAndWrongInput) {
  auto r = read_gmrb("/nonexistent/dir/x.gmrb");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().to_string().find("x.gmrb"), std::string::npos);
  TempDir dir;
  EXPECT_FALSE(read_gmrb(dir.path).ok());  // a directory
  Motion bad = small_motion();
  bad.values.pop_back();
  EXPECT_FALSE(write_gmrb(bad, dir.path / "bad.gmrb").ok());
  EXPECT_FALSE(fs::exists(dir.path / "bad.gmrb"));
}

}  // namespace
}  // namespace gmr
