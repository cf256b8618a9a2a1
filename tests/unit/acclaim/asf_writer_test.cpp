// ASF/AMC writers: read -> write -> read reproduces the files' content exactly.
#include <gtest/gtest.h>

#include <unistd.h>

#include "acclaim_test_util.h"
#include "gmr/core/file_util.h"

namespace gmr::test {
namespace {

void expect_same_skeleton(const AsfSkeleton& a, const AsfSkeleton& b) {
  EXPECT_EQ(a.version, b.version);
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.documentation, b.documentation);
  EXPECT_EQ(a.units.mass, b.units.mass);
  EXPECT_EQ(a.units.length, b.units.length);
  EXPECT_EQ(a.units.degrees, b.units.degrees);
  ASSERT_EQ(a.bones.size(), b.bones.size());
  for (std::size_t i = 0; i < a.bones.size(); ++i) {
    const AsfBone& x = a.bones[i];
    const AsfBone& y = b.bones[i];
    SCOPED_TRACE(x.name);
    EXPECT_EQ(x.id, y.id);
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.parent, y.parent);
    EXPECT_EQ(x.direction, y.direction);
    EXPECT_EQ(x.length, y.length);
    EXPECT_EQ(x.axis, y.axis);
    EXPECT_EQ(x.axis_order, y.axis_order);
    EXPECT_EQ(x.dofs, y.dofs);
    EXPECT_EQ(x.position, y.position);
    ASSERT_EQ(x.limits.size(), y.limits.size());
    for (std::size_t k = 0; k < x.limits.size(); ++k) {
      EXPECT_EQ(x.limits[k].min, y.limits[k].min);
      EXPECT_EQ(x.limits[k].max, y.limits[k].max);
    }
  }
}

// Every corpus pair: parse, write, parse again: identical skeleton, identical
// values, identical positions (exact equality, not a tolerance).
TEST(ReadWriteReadIsExact, AsfAmcWriter) {
  GMR_REQUIRE_DATA();
  for (const auto& [asf, amc] : acclaim_pairs()) {
    SCOPED_TRACE(amc.string());
    auto s = read_asf(asf);
    ASSERT_TRUE(s.ok());
    auto m = read_amc(amc, *s);
    ASSERT_TRUE(m.ok());
    limit_frames(*m, *s);
    const std::string asf_text = format_asf(*s);
    auto amc_text = format_amc(*s, *m);
    ASSERT_TRUE(amc_text.ok());
    auto s2 = parse_asf(asf_text, "written.asf");
    ASSERT_TRUE(s2.ok()) << s2.error().to_string();
    expect_same_skeleton(*s, *s2);
    Warnings w;
    auto m2 = parse_amc(*amc_text, "written.amc", *s2, &w);
    ASSERT_TRUE(m2.ok()) << m2.error().to_string();
    EXPECT_TRUE(w.empty());
    EXPECT_EQ(m2->frame_numbers, m->frame_numbers);
    EXPECT_EQ(m2->degrees, m->degrees);
    EXPECT_TRUE(m2->values == m->values);
    EXPECT_TRUE(acclaim_positions(*s, *m) == acclaim_positions(*s2, *m2));
    // Writing again gives the same bytes.
    EXPECT_EQ(format_asf(*s2), asf_text);
    EXPECT_EQ(*format_amc(*s2, *m2), *amc_text);
  }
}

TEST(WritesRadiansLimitsAndGapsBack, AsfAmcWriter) {
  std::string asf = kSmallAsf;
  asf.replace(asf.find("angle deg"), 9, "angle rad");
  asf.replace(asf.find("(-60.0 70.0)"), 12, "(-inf inf)");
  const AsfSkeleton s = must_parse_asf(asf);
  std::string amc = kSmallAmc;
  amc.replace(amc.find(":DEGREES"), 8, ":RADIANS");
  amc.replace(amc.find("\n2\n"), 3, "\n17\n");
  const AmcMotion m = must_parse_amc(amc, s);
  const AsfSkeleton s2 = must_parse_asf(format_asf(s));
  expect_same_skeleton(s, s2);
  const AmcMotion m2 = must_parse_amc(*format_amc(s2, m), s2);
  EXPECT_FALSE(m2.degrees);
  EXPECT_EQ(m2.frame_numbers, (std::vector<long long>{1, 17}));
  EXPECT_TRUE(m2.values == m.values);
}

TEST(FilesAreWrittenAtomically, AsfAmcWriter) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  const AmcMotion m = must_parse_amc(kSmallAmc, s);
  const auto dir = std::filesystem::temp_directory_path() / ("gmr_asf_writer_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  ASSERT_TRUE(write_asf(s, dir / "s.asf").ok());
  ASSERT_TRUE(write_amc(s, m, dir / "m.amc").ok());
  // Only the two files: no temporary left behind.
  std::size_t n = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) n += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(n, 2u);
  auto s2 = read_asf(dir / "s.asf");
  ASSERT_TRUE(s2.ok());
  auto m2 = read_amc(dir / "m.amc", *s2);
  ASSERT_TRUE(m2.ok());
  EXPECT_TRUE(m2->values == m.values);
  // A motion whose values do not fit the skeleton is refused, and nothing is written.
  AmcMotion bad = m;
  bad.values.pop_back();
  EXPECT_FALSE(write_amc(s, bad, dir / "bad.amc").ok());
  EXPECT_FALSE(std::filesystem::exists(dir / "bad.amc"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace gmr::test
