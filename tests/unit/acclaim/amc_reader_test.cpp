// AMC reader: frame numbering, missing and unknown bones, value counts, units,
// real and truncated files.
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "acclaim_test_util.h"
#include "gmr/core/file_util.h"

namespace gmr::test {
namespace {

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
  for (std::size_t p = s.find(from); p != std::string::npos; p = s.find(from, p + to.size()))
    s.replace(p, from.size(), to);
  return s;
}

TEST(ReadsValuesInDofOrder, Amc) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  const AmcMotion m = must_parse_amc(kSmallAmc, s);
  EXPECT_TRUE(m.fully_specified);
  EXPECT_TRUE(m.degrees);
  ASSERT_EQ(m.frame_count, 2u);
  EXPECT_EQ(m.frame_numbers, (std::vector<long long>{1, 2}));
  const std::size_t stride = static_cast<std::size_t>(s.value_count());
  ASSERT_EQ(stride, 12u);
  const auto f1 = m.frame(1, stride);
  EXPECT_EQ(f1[0], 1.5);  // root TX
  EXPECT_EQ(f1[static_cast<std::size_t>(s.value_offset(s.find("knee")))], 80.0);
  EXPECT_EQ(f1[static_cast<std::size_t>(s.value_offset(s.find("back"))) + 1], 3.0);  // back rx
}

// Pitfall 8: frame numbers need not start at 1 or be gapless; frames are kept in file order.
TEST(FrameNumbersWithGaps, Amc) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  const std::string amc = replace_all(replace_all(kSmallAmc, "\n1\n", "\n40\n"), "\n2\n", "\n45\n");
  Warnings w;
  const AmcMotion m = must_parse_amc(amc, s, &w);
  EXPECT_EQ(m.frame_numbers, (std::vector<long long>{40, 45}));
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].line, 8);
  EXPECT_NE(w[0].message.find("jump from 40 to 45"), std::string::npos);
  // Positions do not depend on the numbering.
  const AmcMotion ref = must_parse_amc(kSmallAmc, s);
  EXPECT_EQ(acclaim_positions(s, m), acclaim_positions(s, ref));
}

TEST(FrameNumbersMustIncrease, Amc) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  auto r = parse_amc(replace_all(kSmallAmc, "\n2\n", "\n1\n"), "dup.amc", s);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().line, 8);
  EXPECT_EQ(r.error().column, 1);
  EXPECT_NE(r.error().message.find("above 1"), std::string::npos);
}

// Pitfall 9: an AMC bone unknown to the ASF is an error with its line.
TEST(UnknownBoneIsAnError, Amc) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  auto r = parse_amc(replace_all(kSmallAmc, "knee 80", "  tail 80"), "u.amc", s);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().to_string(), "u.amc:11:3: bone 'tail' is not in the skeleton");
}

// Decision: a bone missing from a frame keeps 0 (its rest pose), as CMU's
// mocapPlayer and amc_parser do; one warning says how many entries were missing.
TEST(MissingBonesKeepZero, Amc) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  const std::string amc = replace_all(replace_all(kSmallAmc, "knee 80\n", ""), ":FULLY-SPECIFIED\n", "");
  Warnings w;
  const AmcMotion m = must_parse_amc(amc, s, &w);
  EXPECT_FALSE(m.fully_specified);
  EXPECT_EQ(m.frame(1, 12)[static_cast<std::size_t>(s.value_offset(s.find("knee")))], 0.0);
  EXPECT_EQ(m.frame(0, 12)[static_cast<std::size_t>(s.value_offset(s.find("knee")))], 40.0);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].line, 7);  // the frame that lacks it
  EXPECT_NE(w[0].message.find("1 bone entries missing"), std::string::npos);
}

TEST(BrokenInputGivesLineAndColumn, Amc) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  struct Case {
    const char* what;
    std::string from, to;
    std::string error;
  };
  const std::vector<Case> cases = {
      {"too few values", "hip 5 -10 15", "hip 5 -10",
       "b.amc:5:10: expected 3 values for bone 'hip' (dof rx ry rz), found 2"},
      {"too many values", "knee 40", "knee 40 41", "b.amc:6:9: expected 1 values for bone 'knee' (dof rx), found 2"},
      {"fused numbers", "hip 5 -10 15", "hip 5 0.0-7.5 15", "b.amc:5:7: expected a finite number, found '0.0-7.5'"},
      {"nan", "knee 40", "knee nan", "b.amc:6:6: expected a finite number, found 'nan'"},
      {"bone twice", "back 7 -3", "back 7 -3\nBack 1 2", "b.amc:8:1: bone 'Back' listed twice in frame 1"},
      {"data before frame", "1\nroot", "root", "b.amc:3:1: expected a frame number before bone data, found 'root'"},
      {"empty frame", "2\nroot 1.5", "2\n3\nroot 1.5", "b.amc:8:1: expected bone data after frame number 2"},
      {"keyword in frames", "knee 80", ":DEGREES",
       "b.amc:11:1: expected a frame number or a bone name, found ':DEGREES'"},
      {"no frames", kSmallAmc, ":DEGREES\n",
       "b.amc:1:1: expected at least one frame (a frame number, then bone lines)"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.what);
    std::string t = kSmallAmc;
    const auto p = t.find(c.from);
    ASSERT_NE(p, std::string::npos);
    t.replace(p, c.from.size(), c.to);
    auto r = parse_amc(t, "b.amc", s);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().to_string(), c.error);
  }
}

TEST(TruncatedCorpusFile, Amc) {
  GMR_REQUIRE_DATA();
  auto s = read_asf(data_file("asfamc/07/07-walk.asf"));
  ASSERT_TRUE(s.ok()) << s.error().to_string();
  const auto path = data_file("malformed/TRUNC_07_05-walk_mid_frame.amc");
  auto r = read_amc(path, *s);
  ASSERT_FALSE(r.ok());
  // The file ends in the middle of frame 79's root line: "root 9.29735 16.4047 -25."
  EXPECT_EQ(r.error().file, path.string());
  EXPECT_EQ(r.error().line, 2345);
  EXPECT_EQ(r.error().column, 26);  // just past the end of the line, where values are missing
  EXPECT_NE(r.error().message.find("expected 6 values for bone 'root'"), std::string::npos) << r.error().to_string();
}

// Every prefix of the first frames of a real take parses or fails with a
// located error; none crashes.
TEST(EveryPrefixOfARealFile, Amc) {
  GMR_REQUIRE_DATA();
  auto s = read_asf(data_file("asfamc/01/01.asf"));
  ASSERT_TRUE(s.ok());
  auto text = read_file(data_file("asfamc/01/01_01.amc"));
  ASSERT_TRUE(text.ok());
  const std::string_view head = std::string_view(*text).substr(0, 4000);  // 1 header + ~4 frames
  for (std::size_t n = 0; n <= head.size(); ++n) {
    auto r = parse_amc(head.substr(0, n), "prefix.amc", *s);
    if (!r.ok()) {
      EXPECT_GT(r.error().line, 0) << n;
      EXPECT_GT(r.error().column, 0) << n;
    }
  }
}

// A frame that lists no bone is an error, and each frame costs a full row of
// values: a file of frame numbers with little data must not make the reader
// allocate far beyond the file's size.
TEST(AllocationIsBoundedByFileSize, Amc) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  std::string bare;
  for (int i = 1; i < 2000; ++i) bare += std::to_string(i) + "\n";
  auto r = parse_amc(bare, "bare.amc", s);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().to_string(), "bare.amc:1:1: expected bone data after frame number 1");

  // 2000 bones with 3 dofs each: 6006 values a frame, from ~20 bytes of text a frame.
  std::string asf = ":root\n order TX TY TZ RX RY RZ\n:bonedata\n";
  std::string hierarchy = ":hierarchy\n begin\n";
  for (int i = 0; i < 2000; ++i) {
    asf += " begin\n name b" + std::to_string(i) + "\n direction 1 0 0\n length 1\n dof rx ry rz\n end\n";
    hierarchy += (i == 0 ? std::string(" root") : " b" + std::to_string(i - 1)) + " b" + std::to_string(i) + "\n";
  }
  const AsfSkeleton big = must_parse_asf(asf + hierarchy + " end\n");
  ASSERT_EQ(big.value_count(), 6006);
  std::string amc;
  for (int i = 1; i < 200; ++i) amc += std::to_string(i) + "\nroot 0 0 0 0 0 0\n";
  auto m = parse_amc(amc, "sparse.amc", big);
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.error().message.find("too many frames for the size of the file"), std::string::npos)
      << m.error().to_string();
  EXPECT_LT(m.error().line, 60);
}

TEST(ReadsEveryCorpusMotion, Amc) {
  GMR_REQUIRE_DATA();
  const auto pairs = acclaim_pairs();
  ASSERT_GE(pairs.size(), 9u);
  for (const auto& [asf, amc] : pairs) {
    auto s = read_asf(asf);
    ASSERT_TRUE(s.ok()) << s.error().to_string();
    Warnings w;
    auto m = read_amc(amc, *s, &w);
    ASSERT_TRUE(m.ok()) << m.error().to_string();
    EXPECT_TRUE(w.empty()) << w.front().to_string();
    EXPECT_TRUE(m->fully_specified) << amc;
    EXPECT_GT(m->frame_count, 100u) << amc;
    EXPECT_EQ(m->frame_numbers.front(), 1) << amc;
    EXPECT_EQ(m->frame_numbers.back(), static_cast<long long>(m->frame_count)) << amc;
  }
}

// A cheap deterministic fuzzer: random byte edits of a small ASF/AMC pair. Each
// result parses or fails with a located error; what parses converts, runs FK
// and writes without crashing (the sanitizer build checks memory and UB).
TEST(MutatedInputNeverCrashes, AsfAmc) {
  std::mt19937 rng(2012);
  const std::string alphabet = " \t\r\n0123456789.-+eE(),#:abcdefghijklmnopqrstuvwxyzRXTYZ";
  auto mutate = [&](std::string t) {
    const int edits = 1 + static_cast<int>(rng() % 4);
    for (int e = 0; e < edits && !t.empty(); ++e) {
      const std::size_t at = rng() % t.size();
      switch (rng() % 4) {
        case 0:
          t[at] = alphabet[rng() % alphabet.size()];
          break;
        case 1:
          t.erase(at, 1 + rng() % 8);
          break;
        case 2:
          t.insert(at, 1, alphabet[rng() % alphabet.size()]);
          break;
        default:
          t.insert(at, t.substr(rng() % t.size(), rng() % 40));
          break;
      }
    }
    return t;
  };
  int parsed_asf = 0, parsed_amc = 0;
  for (int i = 0; i < 3000; ++i) {
    const bool edit_asf = i % 2 == 0;
    const std::string asf = edit_asf ? mutate(kSmallAsf) : std::string(kSmallAsf);
    const std::string amc = edit_asf ? std::string(kSmallAmc) : mutate(kSmallAmc);
    auto s = parse_asf(asf, "fuzz.asf");
    if (!s.ok()) {
      ASSERT_GT(s.error().line, 0) << asf;
      ASSERT_GT(s.error().column, 0) << asf;
      continue;
    }
    ++parsed_asf;
    auto m = parse_amc(amc, "fuzz.amc", *s);
    if (!m.ok()) {
      ASSERT_GT(m.error().line, 0) << amc;
      ASSERT_GT(m.error().column, 0) << amc;
      continue;
    }
    ++parsed_amc;
    (void)acclaim_positions(*s, *m);
    auto g = acclaim_to_gmr(*s, *m);
    if (g.ok()) (void)gmr_to_acclaim(*g);
    (void)format_asf(*s);
    ASSERT_TRUE(format_amc(*s, *m).ok());
  }
  EXPECT_GT(parsed_asf, 100);
  EXPECT_GT(parsed_amc, 100);
}

}  // namespace
}  // namespace gmr::test
