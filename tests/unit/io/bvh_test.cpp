// BVH reader and writer: every item of the BVH sections of
// ../shared/FORMAT-PITFALLS.md (numbered as there) is a test here, on small
// inline texts; then every real file of the corpus.
#include "gmr/io/bvh.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <random>
#include <string>

#include "gmr/kinematics/forward_kinematics.h"
#include "io_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {

using ::testing::HasSubstr;

Motion parse_ok(std::string_view text, Warnings* warnings = nullptr) {
  auto r = parse_bvh(text, "test.bvh", warnings);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().to_string());
  if (!r.ok()) return Motion{};
  return std::move(r).value();
}

Error parse_error(std::string_view text) {
  auto r = parse_bvh(text, "test.bvh");
  EXPECT_FALSE(r.ok()) << "expected an error";
  if (r.ok()) return Error{};
  EXPECT_EQ(r.error().file, "test.bvh");
  EXPECT_GT(r.error().line, 0) << r.error().to_string();
  EXPECT_GT(r.error().column, 0) << r.error().to_string();
  return r.error();
}

std::string replace_all(std::string s, std::string_view from, std::string_view to) {
  for (std::size_t p = s.find(from); p != std::string::npos; p = s.find(from, p + to.size()))
    s.replace(p, from.size(), to);
  return s;
}

// Two joints and an End Site; 9 channels; 2 frames.
constexpr std::string_view kSimple =
    "HIERARCHY\n"
    "ROOT Hips\n"
    "{\n"
    "\tOFFSET 1 2 3\n"
    "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    "\tJOINT Spine\n"
    "\t{\n"
    "\t\tOFFSET 0 10 0\n"
    "\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n"
    "\t\tEnd Site\n"
    "\t\t{\n"
    "\t\t\tOFFSET 0 5 0\n"
    "\t\t}\n"
    "\t}\n"
    "}\n"
    "MOTION\n"
    "Frames: 2\n"
    "Frame Time: 0.0083333\n"
    "1 2 3 10 20 30 40 50 60\n"
    "4 5 6 -10 -20 -30 -40 -50 -60\n";

TEST(BvhStructure, SimpleFile) {
  Warnings w;
  const Motion m = parse_ok(kSimple, &w);
  EXPECT_TRUE(w.empty());
  ASSERT_EQ(m.skeleton.size(), 3u);
  EXPECT_EQ(m.convention, Convention::kPostRotation);
  EXPECT_EQ(m.skeleton.joint(0).name, "Hips");
  EXPECT_EQ(m.skeleton.joint(1).name, "Spine");
  EXPECT_EQ(m.skeleton.joint(2).name, "Spine_End");
  EXPECT_EQ(m.skeleton.joint(2).parent, 1);
  EXPECT_TRUE(m.skeleton.joint(2).channels.empty());
  EXPECT_EQ(m.skeleton.joint(0).offset, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(m.frame_count, 2u);
  EXPECT_EQ(m.frame_time, 0.0083333);
  ASSERT_EQ(m.values.size(), 18u);
  EXPECT_EQ(m.values[9], 4.0);
  EXPECT_EQ(m.values[17], -60.0);
  EXPECT_TRUE(m.validate().ok());
}

// 1. Any whitespace: tabs, CR-only, CRLF, mixed line ends.
TEST(BvhPitfall1Whitespace, TabsCrOnlyCrlfMixed) {
  const Motion ref = parse_ok(kSimple);
  const std::string variants[] = {
      replace_all(std::string(kSimple), "\n", "\r\n"), replace_all(std::string(kSimple), "\n", "\r"),
      replace_all(replace_all(std::string(kSimple), " ", "\t \t"), "Frame Time:", "Frame Time:\t"),
      // 02_01.bvh style: CRLF in the hierarchy, LF in MOTION.
      replace_all(std::string(kSimple.substr(0, kSimple.find("MOTION"))), "\n", "\r\n") +
          std::string(kSimple.substr(kSimple.find("MOTION"))),
      "\xEF\xBB\xBF" + std::string(kSimple),  // UTF-8 byte order mark
  };
  for (const std::string& text : variants) {
    Warnings w;
    const Motion m = parse_ok(text, &w);
    EXPECT_TRUE(w.empty());
    EXPECT_EQ(m.values, ref.values);
    EXPECT_EQ(m.frame_time, ref.frame_time);
    ASSERT_EQ(m.skeleton.size(), ref.skeleton.size());
    for (int j = 0; j < 3; ++j) EXPECT_EQ(m.skeleton.joint(j).name, ref.skeleton.joint(j).name);
  }
}

TEST(BvhPitfall1Whitespace, CrOnlyErrorLinesCountCarriageReturns) {
  std::string text = replace_all(std::string(kSimple), "\n", "\r");
  text = replace_all(text, "OFFSET 0 10 0", "OFFSET 0 1x0 0");
  const Error e = parse_error(text);
  EXPECT_EQ(e.line, 8);
}

TEST(BvhPitfall1Numbers, LeadingDotExponentsAndPlus) {
  std::string text = std::string(kSimple);
  text = replace_all(text, "1 2 3 10 20 30 40 50 60", ".5 -.25 1E-7 1e+02 2.5E2 +3 -0 0.0 1e-320");
  const Motion m = parse_ok(text);
  EXPECT_EQ(m.values[0], 0.5);
  EXPECT_EQ(m.values[1], -0.25);
  EXPECT_EQ(m.values[2], 1e-7);
  EXPECT_EQ(m.values[3], 100.0);
  EXPECT_EQ(m.values[4], 250.0);
  EXPECT_EQ(m.values[5], 3.0);
  EXPECT_EQ(m.values[6], 0.0);
  EXPECT_GT(m.values[8], 0.0);  // a subnormal, not an error
  EXPECT_EQ(m.frame_time, 0.0083333);
}

// The reader's number fast path gives exactly what std::from_chars gives.
TEST(BvhPitfall1Numbers, EveryDecimalReadsAsFromCharsReadsIt) {
  std::mt19937_64 rng(7);
  std::vector<std::string> numbers;
  auto digits = [&](int n) {
    std::string d;
    for (int i = 0; i < n; ++i) d += static_cast<char>('0' + rng() % 10);
    return d;
  };
  for (int i = 0; i < 20000; ++i) {
    std::string t = rng() % 2 ? "-" : "";
    t += digits(static_cast<int>(rng() % 21));
    if (rng() % 4 != 0) {
      t += '.';
      t += digits(static_cast<int>(rng() % 26));
    }
    if (t.find_first_of("0123456789") == std::string::npos) t += '0';
    if (rng() % 10 == 0) {
      t += 'e';
      t += std::to_string(static_cast<int>(rng() % 40) - 20);
    }
    numbers.push_back(t);
  }
  numbers.insert(numbers.end(), {"9007199254740993", "9007199254740992.5", "0.1", "123456789012345678901", "-0",
                                 "1.7976931348623157e308", "4.9e-324", "0.000000000000000000000001", "5."});
  std::string text =
      "HIERARCHY\nROOT A\n{\nOFFSET 0 0 0\nCHANNELS 1 Xposition\n}\nMOTION\nFrames: " + std::to_string(numbers.size()) +
      "\nFrame Time: 1\n";
  for (const std::string& n : numbers) text += n + "\n";
  const Motion m = parse_ok(text);
  ASSERT_EQ(m.values.size(), numbers.size());
  for (std::size_t i = 0; i < numbers.size(); ++i) {
    double expected = 0;
    const auto r = std::from_chars(numbers[i].data(), numbers[i].data() + numbers[i].size(), expected);
    ASSERT_TRUE(r.ec == std::errc() && r.ptr == numbers[i].data() + numbers[i].size()) << numbers[i];
    ASSERT_EQ(std::signbit(m.values[i]), std::signbit(expected)) << numbers[i];
    ASSERT_EQ(m.values[i], expected) << numbers[i];
  }
}

// 2. Fused numbers are an error with line:column.
TEST(BvhPitfall2FusedNumbers, InMotionRow) {
  const std::string text = replace_all(std::string(kSimple), "4 5 6 -10", "4 5 0.0-7.5 -10");
  const Error e = parse_error(text);
  EXPECT_EQ(e.line, 20);
  EXPECT_EQ(e.column, 8);  // the '-' that should have been a space
  EXPECT_THAT(e.message, HasSubstr("0.0-7.5"));
  EXPECT_THAT(e.to_string(), HasSubstr("test.bvh:20:8:"));
}

TEST(BvhPitfall2FusedNumbers, InOffset) {
  const Error e = parse_error(replace_all(std::string(kSimple), "OFFSET 0 10 0", "OFFSET 0.0-7.5 10 0"));
  EXPECT_EQ(e.line, 8);
  EXPECT_THAT(e.message, HasSubstr("0.0-7.5"));
}

TEST(BvhPitfall2FusedNumbers, GarbageValue) {
  const Error e = parse_error(replace_all(std::string(kSimple), "-40 -50", "-40 abc"));
  EXPECT_EQ(e.line, 20);
  EXPECT_THAT(e.message, HasSubstr("expected a number"));
  EXPECT_THAT(e.message, HasSubstr("'abc'"));
}

TEST(BvhPitfall2FusedNumbers, NonFiniteValues) {
  for (const char* bad : {"nan", "inf", "-inf", "1e999"}) {
    const Error e = parse_error(replace_all(std::string(kSimple), "-40 -50", std::string("-40 ") + bad));
    EXPECT_EQ(e.line, 20) << bad;
  }
}

// 3. Names with spaces, ':' and '.' are kept as written.
TEST(BvhPitfall3Names, SpacesColonsDots) {
  std::string text = replace_all(std::string(kSimple), "ROOT Hips", "ROOT mixamorig:Hips");
  text = replace_all(text, "JOINT Spine", "JOINT  Left Up.Leg 2 ");
  const Motion m = parse_ok(text);
  EXPECT_EQ(m.skeleton.joint(0).name, "mixamorig:Hips");
  EXPECT_EQ(m.skeleton.joint(1).name, "Left Up.Leg 2");
  EXPECT_EQ(m.skeleton.joint(2).name, "Left Up.Leg 2_End");
}

TEST(BvhPitfall3Names, InnerTabsRoundTripControlCharactersAreErrors) {
  const Motion m = parse_ok(replace_all(std::string(kSimple), "JOINT Spine", "JOINT Spine\tUpper"));
  EXPECT_EQ(m.skeleton.joint(1).name, "Spine\tUpper");
  EXPECT_EQ(parse_ok(format_bvh(m).value()).skeleton.joint(1).name, "Spine\tUpper");
  const Error e = parse_error(replace_all(std::string(kSimple), "JOINT Spine", std::string("JOINT Sp\0ine", 12)));
  EXPECT_EQ(e.line, 6);
  EXPECT_EQ(e.column, 10);
  EXPECT_THAT(e.message, HasSubstr("control character"));
}

TEST(BvhPitfall3Names, BraceOnTheNameLine) {
  std::string text = replace_all(std::string(kSimple), "JOINT Spine\n\t{", "JOINT Spine {");
  const Motion m = parse_ok(text);
  EXPECT_EQ(m.skeleton.joint(1).name, "Spine");
  EXPECT_EQ(m.skeleton.size(), 3u);
}

TEST(BvhPitfall3Names, DuplicateNameIsAnError) {
  const Error e = parse_error(replace_all(std::string(kSimple), "JOINT Spine", "JOINT Hips"));
  EXPECT_EQ(e.line, 6);
  EXPECT_THAT(e.message, HasSubstr("duplicate joint name 'Hips'"));
  EXPECT_THAT(e.message, HasSubstr("line 2"));
}

TEST(BvhPitfall3Names, MissingName) {
  const Error e = parse_error(replace_all(std::string(kSimple), "JOINT Spine", "JOINT"));
  EXPECT_EQ(e.line, 6);
  EXPECT_THAT(e.message, HasSubstr("joint name"));
}

// 4. End Site / End site, with or without a name; a joint named "End" is a joint.
TEST(BvhPitfall4EndSite, SpellingsNamesAndDefaults) {
  const std::string text =
      "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 3 Xrotation Yrotation Zrotation\n"
      " End Site\n {\n  OFFSET 1 0 0\n }\n"
      " end site\n {\n  OFFSET 2 0 0\n }\n"
      " End Site LeftToe Tip\n {\n  OFFSET 3 0 0\n }\n"
      " JOINT End\n {\n  OFFSET 0 1 0\n  CHANNELS 1 Zrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n"
      " End Site\n {\n  OFFSET 4 0 0\n }\n"
      "}\nMOTION\nFrames: 1\nFrame Time: 1\n0 0 0 0\n";
  const Motion m = parse_ok(text);
  ASSERT_EQ(m.skeleton.size(), 7u);
  EXPECT_EQ(m.skeleton.joint(1).name, "Hips_End");
  EXPECT_EQ(m.skeleton.joint(2).name, "Hips_End2");
  EXPECT_EQ(m.skeleton.joint(3).name, "LeftToe Tip");
  EXPECT_EQ(m.skeleton.joint(4).name, "End");
  EXPECT_EQ(m.skeleton.joint(4).channels.size(), 1u);
  EXPECT_EQ(m.skeleton.joint(5).name, "End_End");
  EXPECT_EQ(m.skeleton.joint(6).name, "Hips_End3");
  EXPECT_EQ(m.skeleton.joint(6).offset.x(), 4.0);
}

TEST(BvhPitfall4EndSite, DefaultNameAvoidsTakenNames) {
  const std::string text =
      "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 0\n"
      " JOINT Hips_End\n {\n  OFFSET 0 1 0\n }\n"
      " End Site\n {\n  OFFSET 1 0 0\n }\n"
      "}\nMOTION\nFrames: 0\nFrame Time: 1\n";
  const Motion m = parse_ok(text);
  EXPECT_EQ(m.skeleton.joint(2).name, "Hips_End2");
}

TEST(BvhPitfall4EndSite, ChildrenOfAnEndSiteAreAnError) {
  const Error e = parse_error(replace_all(std::string(kSimple), "\t\t\tOFFSET 0 5 0\n",
                                          "\t\t\tOFFSET 0 5 0\n\t\t\tJOINT X\n\t\t\t{\n\t\t\t}\n"));
  EXPECT_EQ(e.line, 13);
  EXPECT_THAT(e.message, HasSubstr("End Site cannot have children"));
}

TEST(BvhPitfall4EndSite, EndWithoutSite) {
  const Error e = parse_error(replace_all(std::string(kSimple), "End Site", "End Zone"));
  EXPECT_EQ(e.line, 10);
  EXPECT_THAT(e.message, HasSubstr("'Site'"));
}

// 5. 3- and 6-channel joints mixed, channels in any order, count must match.
TEST(BvhPitfall5Channels, AnyOrderPositionsAfterRotations) {
  // pybvh_rotation_first_root: the root lists rotations before positions.
  std::string text =
      replace_all(std::string(kSimple), "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
                  "CHANNELS 6 Zrotation Xrotation Yrotation Xposition Yposition Zposition");
  text = replace_all(text, "CHANNELS 3 Zrotation Xrotation Yrotation",
                     "CHANNELS 6 Yrotation Xposition Zrotation Yposition Xrotation Zposition");
  text = replace_all(text, "1 2 3 10 20 30 40 50 60", "10 20 30 1 2 3 40 7 50 8 60 9");
  text = replace_all(text, "4 5 6 -10 -20 -30 -40 -50 -60", "0 0 0 0 0 0 0 0 0 0 0 0");
  const Motion m = parse_ok(text);
  ASSERT_EQ(m.stride(), 12u);
  EXPECT_EQ(m.local_offset(0, 0), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(m.local_offset(0, 1), Eigen::Vector3d(7, 8, 9));  // position channels replace the OFFSET
  EXPECT_TRUE(m.local_rotation(0, 1).isApprox(
      axis_rotation(Axis::kY, 40) * axis_rotation(Axis::kZ, 50) * axis_rotation(Axis::kX, 60), 1e-15));
}

TEST(BvhPitfall5Channels, FewerNamesThanTheCount) {
  const Error e = parse_error(replace_all(std::string(kSimple), "CHANNELS 3 Zrotation Xrotation Yrotation",
                                          "CHANNELS 4 Zrotation Xrotation Yrotation"));
  EXPECT_EQ(e.line, 10);
  EXPECT_THAT(e.message, HasSubstr("CHANNELS 4 lists 3"));
}

TEST(BvhPitfall5Channels, MoreNamesThanTheCount) {
  const Error e = parse_error(replace_all(std::string(kSimple), "CHANNELS 3 Zrotation Xrotation Yrotation",
                                          "CHANNELS 2 Zrotation Xrotation Yrotation"));
  EXPECT_EQ(e.line, 9);
  EXPECT_THAT(e.message, HasSubstr("more names follow"));
}

TEST(BvhPitfall5Channels, BadCountsAndNames) {
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "CHANNELS 3 Z", "CHANNELS 7 Z")).message,
              HasSubstr("0 to 6"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "CHANNELS 3 Z", "CHANNELS -3 Z")).message,
              HasSubstr("channel count"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "3 Zrotation Xrotation", "3 Zrotation Wrotation")).message,
              HasSubstr("'Wrotation'"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "3 Zrotation Xrotation", "3 Zrotation Zrotation")).message,
              HasSubstr("listed twice"));
  const Error e = parse_error(replace_all(std::string(kSimple), "\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n",
                                          "\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n\t\tCHANNELS 0\n"));
  EXPECT_THAT(e.message, HasSubstr("second CHANNELS"));
}

TEST(BvhPitfall5Channels, MixOfThreeAndSixAndNone) {
  const std::string text =
      "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
      " JOINT B\n {\n  OFFSET 0 1 0\n  CHANNELS 0\n"
      "  JOINT C\n  {\n   OFFSET 0 1 0\n   CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
      "   JOINT D\n   {\n    OFFSET 0 1 0\n   }\n  }\n }\n}\n"
      "MOTION\nFrames: 1\nFrame Time: 0.1\n1 2 3 4 5 6 7 8 9 10 11 12\n";
  Warnings w;
  const Motion m = parse_ok(text, &w);
  ASSERT_EQ(m.stride(), 12u);
  EXPECT_TRUE(m.skeleton.joint(1).channels.empty());
  EXPECT_TRUE(m.skeleton.joint(3).channels.empty());  // no CHANNELS line: none
  EXPECT_EQ(m.skeleton.channel_offset(2), 6);
  EXPECT_TRUE(w.empty());
}

// 6. CHANNELS after a child JOINT: columns follow the CHANNELS lines; depth is capped.
TEST(BvhPitfall6ChannelsAfterChild, ValuesGoToTheRightJoints) {
  const std::string text =
      "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n"
      " JOINT B\n {\n  OFFSET 0 1 0\n  CHANNELS 1 Zrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n"
      " CHANNELS 2 Xposition Zrotation\n"
      "}\nMOTION\nFrames: 2\nFrame Time: 0.1\n30 5 90\n-30 6 0\n";
  const Motion m = parse_ok(text);
  // Columns: B's Zrotation (CHANNELS line first in the file), then A's two.
  ASSERT_EQ(m.stride(), 3u);
  EXPECT_EQ(m.joint_values(0, 0)[0], 5.0);
  EXPECT_EQ(m.joint_values(0, 0)[1], 90.0);
  EXPECT_EQ(m.joint_values(0, 1)[0], 30.0);
  EXPECT_EQ(m.joint_values(1, 0)[0], 6.0);
  EXPECT_EQ(m.joint_values(1, 1)[0], -30.0);
}

TEST(BvhPitfall6ChannelsAfterChild, DeepNestingIsCappedNotACrash) {
  std::string text = "HIERARCHY\nROOT J0\n{\n";
  for (int i = 1; i < 5000; ++i) text += "JOINT J" + std::to_string(i) + "\n{\n";
  const Error e = parse_error(text);
  EXPECT_THAT(e.message, HasSubstr("nested deeper"));
}

// 7. Several ROOT blocks give a forest.
TEST(BvhPitfall7SeveralRoots, Forest) {
  std::string text = std::string(kSimple.substr(0, kSimple.find("MOTION")));
  text += "ROOT Prop\n{\n OFFSET 5 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\n";
  text += "MOTION\nFrames: 1\nFrame Time: 0.1\n1 2 3 10 20 30 40 50 60 7 8 9\n";
  const Motion m = parse_ok(text);
  ASSERT_EQ(m.skeleton.roots().size(), 2u);
  EXPECT_EQ(m.skeleton.joint(m.skeleton.roots()[1]).name, "Prop");
  std::vector<Eigen::Vector3d> p(m.skeleton.size());
  compute_frame(m, 0, p);
  EXPECT_EQ(p[3], Eigen::Vector3d(7, 8, 9));
}

// 8. Frames vs rows: wrapped values, trailing blank lines, mismatches.
TEST(BvhPitfall8Frames, ValuesWrapAcrossLinesAndTrailingBlankLines) {
  const std::string text = replace_all(std::string(kSimple), "4 5 6 -10 -20 -30 -40 -50 -60\n",
                                       "4 5 6\n-10 -20 -30\n\n-40 -50 -60\n\n\n  \n");
  Warnings w;
  const Motion m = parse_ok(text, &w);
  EXPECT_TRUE(w.empty());
  EXPECT_EQ(m.values, parse_ok(kSimple).values);
}

TEST(BvhPitfall8Frames, MoreRowsThanDeclaredLoadsAllWithAWarning) {
  const std::string text = replace_all(std::string(kSimple), "Frames: 2", "Frames: 1");
  Warnings w;
  const Motion m = parse_ok(text, &w);
  EXPECT_EQ(m.frame_count, 2u);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].line, 17);
  EXPECT_THAT(w[0].message, HasSubstr("'Frames: 1' but the file holds 2"));
}

TEST(BvhPitfall8Frames, FewerRowsThanDeclaredLoadsThemWithAWarning) {
  const std::string text = replace_all(std::string(kSimple), "Frames: 2", "Frames: 3");
  Warnings w;
  const Motion m = parse_ok(text, &w);
  EXPECT_EQ(m.frame_count, 2u);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_THAT(w[0].message, HasSubstr("'Frames: 3' but the file holds 2"));
}

TEST(BvhPitfall8Frames, TruncatedMidFrameIsAnError) {
  const std::string text = std::string(kSimple.substr(0, kSimple.size() - 8));  // "4 5 6 -10 -20 -30 -4"
  const Error e = parse_error(text);
  EXPECT_EQ(e.line, 20);
  EXPECT_THAT(e.message, HasSubstr("file ends in frame 1"));
  EXPECT_THAT(e.message, HasSubstr("7 of its 9 values"));
}

TEST(BvhPitfall8Frames, NoRowsAtAllIsAnError) {
  const std::string text = std::string(kSimple.substr(0, kSimple.find("1 2 3 10")));
  EXPECT_THAT(parse_error(text).message, HasSubstr("no frame data"));
}

TEST(BvhPitfall8Frames, ZeroFramesIsAValidEmptyMotion) {
  std::string text = std::string(kSimple.substr(0, kSimple.find("1 2 3 10")));
  text = replace_all(text, "Frames: 2", "Frames: 0");
  Warnings w;
  const Motion m = parse_ok(text, &w);
  EXPECT_EQ(m.frame_count, 0u);
  EXPECT_TRUE(m.values.empty());
  EXPECT_TRUE(w.empty());
}

TEST(BvhPitfall8Frames, FramesHeaderSpellings) {
  for (const char* frames : {"Frames:    2", "Frames:\t2", "Frames:2", "FRAMES: 2"}) {
    const Motion m = parse_ok(replace_all(std::string(kSimple), "Frames: 2", frames));
    EXPECT_EQ(m.frame_count, 2u) << frames;
  }
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "Frames: 2", "Frames: two")).message,
              HasSubstr("frame count"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "Frames: 2", "Fames: 2")).message, HasSubstr("'Frames:'"));
}

// 9. Frame Time 0 or missing: a warning, never a division by zero.
TEST(BvhPitfall9FrameTime, ZeroWarns) {
  Warnings w;
  const Motion m = parse_ok(replace_all(std::string(kSimple), "Frame Time: 0.0083333", "Frame Time: 0"), &w);
  EXPECT_EQ(m.frame_time, 0.0);
  EXPECT_EQ(m.duration(), 0.0);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].line, 18);
  EXPECT_THAT(w[0].message, HasSubstr("Frame Time is 0"));
}

TEST(BvhPitfall9FrameTime, MissingWarns) {
  Warnings w;
  const Motion m = parse_ok(replace_all(std::string(kSimple), "Frame Time: 0.0083333\n", ""), &w);
  EXPECT_EQ(m.frame_time, 0.0);
  EXPECT_EQ(m.frame_count, 2u);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_THAT(w[0].message, HasSubstr("no 'Frame Time:'"));
}

TEST(BvhPitfall9FrameTime, GluedFullPrecisionAndNegative) {
  EXPECT_EQ(
      parse_ok(replace_all(std::string(kSimple), "Frame Time: 0.0083333", "Frame Time:0.0417083750417")).frame_time,
      0.0417083750417);
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "Frame Time: 0.0083333", "Frame Time: -1")).message,
              HasSubstr("negative"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "Frame Time: 0.0083333", "Frame Time: fast")).message,
              HasSubstr("frame time"));
}

// 10. A declared size never reserves more than the bytes left can hold.
TEST(BvhPitfall10DeclaredSizes, HugeFrameCountOnATinyFile) {
  Warnings w;
  const Motion m = parse_ok(replace_all(std::string(kSimple), "Frames: 2", "Frames: 1000000000000000000"), &w);
  EXPECT_EQ(m.frame_count, 2u);
  EXPECT_LT(m.values.capacity(), 1000u);
  EXPECT_EQ(w.size(), 1u);
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "Frames: 2", "Frames: 99999999999999999999999")).message,
              HasSubstr("out of range"));
}

// 11 and 12. Euler channels compose in listed order, intrinsic, degrees.
TEST(BvhPitfall11EulerOrder, ListedOrderIntrinsicDegrees) {
  const Motion m = parse_ok(kSimple);
  // Hips: Zrotation Xrotation Yrotation = 10 20 30 -> Rz(10) Rx(20) Ry(30).
  const Eigen::Matrix3d R = axis_rotation(Axis::kZ, 10) * axis_rotation(Axis::kX, 20) * axis_rotation(Axis::kY, 30);
  EXPECT_TRUE(m.local_rotation(0, 0).isApprox(R, 1e-15));
  std::vector<Eigen::Vector3d> p(3);
  compute_frame(m, 0, p);
  EXPECT_TRUE(p[1].isApprox(Eigen::Vector3d(1, 2, 3) + R * Eigen::Vector3d(0, 10, 0), 1e-14));
}

// 13. Position channels REPLACE the OFFSET (a large root OFFSET does not add).
TEST(BvhPitfall13PositionChannels, ReplaceTheOffset) {
  const Motion m = parse_ok(replace_all(std::string(kSimple), "OFFSET 1 2 3", "OFFSET 100 200 300"));
  std::vector<Eigen::Vector3d> p(3);
  compute_frame(m, 0, p);
  EXPECT_EQ(p[0], Eigen::Vector3d(1, 2, 3));
}

// 14. One or two rotation channels: the missing axes are 0.
TEST(BvhPitfall14FewRotationChannels, MissingAxesAreZero) {
  std::string text =
      replace_all(std::string(kSimple), "CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 2 Yrotation Xrotation");
  text = replace_all(text, "1 2 3 10 20 30 40 50 60", "0 0 0 0 0 0 90 45");
  text = replace_all(text, "4 5 6 -10 -20 -30 -40 -50 -60", "0 0 0 0 0 0 0 0");
  const Motion m = parse_ok(text);
  EXPECT_TRUE(m.local_rotation(0, 1).isApprox(axis_rotation(Axis::kY, 90) * axis_rotation(Axis::kX, 45), 1e-15));
}

TEST(BvhStructure, MissingOffsetWarns) {
  Warnings w;
  const Motion m = parse_ok(replace_all(std::string(kSimple), "\t\tOFFSET 0 10 0\n", ""), &w);
  EXPECT_EQ(m.skeleton.joint(1).offset, Eigen::Vector3d::Zero());
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].line, 6);
  EXPECT_THAT(w[0].message, HasSubstr("no OFFSET"));
}

TEST(BvhStructure, ErrorsNameWhatWasExpected) {
  EXPECT_THAT(parse_error("").message, HasSubstr("expected 'HIERARCHY', found end of file"));
  EXPECT_THAT(parse_error("HIERARCHY\nMOTION\n").message, HasSubstr("expected ROOT, found 'MOTION'"));
  EXPECT_THAT(parse_error("HIERARCHY\nROOT A\nOFFSET 0 0 0\n").message, HasSubstr("expected '{' after ROOT 'A'"));
  const Error unclosed = parse_error(std::string(kSimple.substr(0, kSimple.find("\t}\n}"))) + "MOTION\n");
  EXPECT_THAT(unclosed.message, HasSubstr("opened at line 7 is not closed"));
  const Error eof = parse_error(kSimple.substr(0, kSimple.find("\t\tEnd Site")));
  EXPECT_THAT(eof.message, HasSubstr("found end of file"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "OFFSET 0 10 0", "OFFSET 0 10")).message,
              HasSubstr("expected an OFFSET value, found 'CHANNELS'"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "\tJOINT Spine", "\tJIONT Spine")).message,
              HasSubstr("expected OFFSET, CHANNELS, JOINT, End Site or '}' in joint 'Hips', found 'JIONT'"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "OFFSET 1 2 3\n", "OFFSET 1 2 3\nOFFSET 1 2 3\n")).message,
              HasSubstr("second OFFSET"));
  EXPECT_THAT(parse_error(replace_all(std::string(kSimple), "}\nMOTION", "}\nJUNK")).message,
              HasSubstr("expected ROOT or MOTION, found 'JUNK'"));
  EXPECT_THAT(parse_error(std::string(kSimple) + "\x01").message, HasSubstr("'\\x01'"));
}

// ---- writer

TEST(BvhWriter, RoundTripIsExact) {
  Motion m = parse_ok(kSimple);
  m.values[3] = 0.1 + 0.2;  // needs 17 digits
  m.values[4] = -1.0 / 3.0;
  m.values[5] = 1e-300;
  m.skeleton = Skeleton::create([&] {
                 auto j = m.skeleton.joints();
                 j[1].offset = {1.0 / 7.0, -2.5e-12, 123456789.125};
                 return j;
               }())
                   .value();
  const std::string text = format_bvh(m).value();
  const Motion back = parse_ok(text);
  EXPECT_EQ(back.values, m.values);
  EXPECT_EQ(back.frame_time, m.frame_time);
  for (int j = 0; j < 3; ++j) {
    EXPECT_EQ(back.skeleton.joint(j).name, m.skeleton.joint(j).name);
    EXPECT_EQ(back.skeleton.joint(j).offset, m.skeleton.joint(j).offset);
    EXPECT_EQ(back.skeleton.joint(j).channels, m.skeleton.joint(j).channels);
  }
  EXPECT_EQ(format_bvh(back).value(), text);
  EXPECT_THAT(text, HasSubstr("End Site\n"));  // default name: written without it
}

TEST(BvhWriter, NamedEndSitesAndLeafJointsKeepTheirNames) {
  const std::string text =
      "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 0\n"
      " End Site Nose\n {\n  OFFSET 1 0 0\n }\n"
      " End Site\n {\n  OFFSET 2 0 0\n }\n"
      " JOINT Leaf\n {\n  OFFSET 3 0 0\n  CHANNELS 1 Xrotation\n }\n"
      "}\nMOTION\nFrames: 1\nFrame Time: 0.5\n7\n";
  const Motion m = parse_ok(text);
  const std::string out = format_bvh(m).value();
  // `End Site <name>` is not standard BVH: a named leaf is a JOINT with CHANNELS 0.
  EXPECT_THAT(out, HasSubstr("JOINT Nose\n"));
  EXPECT_EQ(out.find("End Site Nose"), std::string::npos);
  EXPECT_THAT(out, HasSubstr("End Site\n"));
  EXPECT_THAT(out, HasSubstr("JOINT Leaf\n"));
  const Motion back = parse_ok(out);
  ASSERT_EQ(back.skeleton.size(), 4u);
  EXPECT_EQ(back.skeleton.joint(1).name, "Nose");
  EXPECT_EQ(back.skeleton.joint(2).name, "Hips_End");
  EXPECT_EQ(back.skeleton.joint(3).name, "Leaf");
  EXPECT_EQ(back.values, m.values);
}

TEST(BvhWriter, EndSiteNamesMirrorTheReader) {
  // Named and unnamed End Sites interleaved, and a JOINT that takes a default name.
  const std::string text =
      "HIERARCHY\nROOT P\n{\n OFFSET 0 0 0\n CHANNELS 0\n"
      " End Site Nose\n {\n  OFFSET 1 0 0\n }\n"
      " End Site\n {\n  OFFSET 2 0 0\n }\n"
      " JOINT P_End2\n {\n  OFFSET 3 0 0\n }\n"
      " End Site\n {\n  OFFSET 4 0 0\n }\n"
      "}\nMOTION\nFrames: 0\nFrame Time: 1\n";
  const Motion m = parse_ok(text);
  ASSERT_EQ(m.skeleton.size(), 5u);
  EXPECT_EQ(m.skeleton.joint(2).name, "P_End");
  EXPECT_EQ(m.skeleton.joint(3).name, "P_End2");
  EXPECT_EQ(m.skeleton.joint(4).name, "P_End3");
  const std::string out = format_bvh(m).value();
  // Nose stays named, on a JOINT; the others (the channel-less leaf JOINT
  // P_End2 too) are exactly what the reader names unnamed End Sites at their
  // places, so they are plain End Sites.
  EXPECT_THAT(out, HasSubstr("JOINT Nose\n"));
  EXPECT_EQ(out.find("End Site P_End"), std::string::npos);
  EXPECT_EQ(out.find("JOINT"), out.rfind("JOINT"));
  const Motion back = parse_ok(out);
  for (int j = 0; j < 5; ++j) EXPECT_EQ(back.skeleton.joint(j).name, m.skeleton.joint(j).name);
}

TEST(BvhPitfall10DeclaredSizes, WarningsAreCapped) {
  std::string text = "HIERARCHY\nROOT P\n{\n";
  for (int i = 0; i < 5000; ++i) text += "JOINT J" + std::to_string(i) + "\n{\n}\n";
  text += "}\nMOTION\nFrames: 0\n";
  Warnings w;
  const Motion m = parse_ok(text, &w);
  EXPECT_EQ(m.skeleton.size(), 5001u);
  ASSERT_EQ(w.size(), 101u);
  EXPECT_EQ(w.back().message, "4902 more warnings not shown");  // 5001 without OFFSET + no Frame Time
}

TEST(BvhPitfall10DeclaredSizes, ManyEndSitesUnderOneParentParseInLinearTime) {
  std::string text = "HIERARCHY\nROOT P\n{\nOFFSET 0 0 0\n";
  for (int i = 0; i < 20000; ++i) text += "End Site\n{\nOFFSET 0 0 0\n}\n";
  text += "}\nMOTION\nFrames: 0\nFrame Time: 1\n";
  const Motion m = parse_ok(text);
  ASSERT_EQ(m.skeleton.size(), 20001u);
  EXPECT_EQ(m.skeleton.joint(20000).name, "P_End20000");
  EXPECT_EQ(parse_ok(format_bvh(m).value()).skeleton.joint(20000).name, "P_End20000");
}

// A forest whose joints are not stored depth-first (operations reorder joints):
// the writer writes each tree depth-first and moves the values with the joints.
TEST(BvhWriter, ForestInBreadthFirstOrder) {
  //   A (root)          P (root)
  //  / \                 |
  // B   C                Q
  // |
  // D
  auto joint = [](std::string name, int parent, Eigen::Vector3d off, std::vector<ChannelType> ch) {
    Joint j;
    j.name = std::move(name);
    j.parent = parent;
    j.offset = off;
    j.channels = std::move(ch);
    return j;
  };
  using C = ChannelType;
  std::vector<Joint> joints = {
      joint("A", -1, {0, 0, 0}, {C::kXposition, C::kYposition, C::kZposition, C::kZrotation}),
      joint("P", -1, {5, 0, 0}, {C::kXrotation}),
      joint("B", 0, {0, 1, 0}, {C::kXrotation, C::kYrotation}),
      joint("C", 0, {1, 0, 0}, {}),
      joint("Q", 1, {0, 0, 2}, {C::kYrotation}),
      joint("D", 2, {0, 1, 0}, {C::kZrotation}),
  };
  Motion m;
  m.skeleton = Skeleton::create(joints).value();
  m.convention = Convention::kPostRotation;
  m.frame_time = 0.25;
  m.frame_count = 2;
  for (int f = 0; f < 2; ++f)
    for (int c = 0; c < m.skeleton.channel_count(); ++c) m.values.push_back(10.0 * f + c + 0.5);
  const std::string text = format_bvh(m).value();
  EXPECT_NE(text.find("ROOT A\n"), std::string::npos);
  EXPECT_NE(text.find("ROOT P\n"), std::string::npos);
  const Motion back = parse_ok(text);
  ASSERT_EQ(back.skeleton.size(), 6u);
  EXPECT_EQ(back.skeleton.joint(1).name, "B");  // depth-first: A B D C P Q
  EXPECT_EQ(back.skeleton.joint(2).name, "D");
  EXPECT_EQ(back.skeleton.joint(3).name, "C");  // a channel-less leaf not named C_End: a JOINT
  EXPECT_NE(text.find("JOINT C\n"), std::string::npos);
  const auto pa = compute_positions(m);
  const auto pb = compute_positions(back);
  for (int j = 0; j < 6; ++j) {
    const std::string& name = m.skeleton.joint(j).name;
    const int k = back.skeleton.find(name);
    ASSERT_GE(k, 0) << name;
    for (std::size_t f = 0; f < 2; ++f) {
      EXPECT_EQ(pa[f * 6 + j], pb[f * 6 + k]) << name;
      const auto va = m.joint_values(f, j);
      const auto vb = back.joint_values(f, k);
      EXPECT_TRUE(std::equal(va.begin(), va.end(), vb.begin(), vb.end())) << name;
    }
  }
}

TEST(BvhWriter, RefusesWhatItCannotWrite) {
  Motion m = parse_ok(kSimple);
  m.convention = Convention::kPreRotation;
  EXPECT_THAT(format_bvh(m).error().message, HasSubstr("post-rotation"));
  m.convention = Convention::kPostRotation;
  m.values.pop_back();
  EXPECT_FALSE(format_bvh(m).ok());
  for (const char* bad : {" lead", "trail ", "two\nlines", "brace {"}) {
    Motion n = parse_ok(kSimple);
    auto j = n.skeleton.joints();
    j[1].name = bad;
    n.skeleton = Skeleton::create(j).value();
    EXPECT_THAT(format_bvh(n).error().message, HasSubstr("cannot be written")) << bad;
  }
  EXPECT_FALSE(format_bvh(Motion{}).ok());
}

// ---- the real corpus

TEST(BvhRealFiles, EveryBvhLoadsAndRoundTripsExactly) {
  GMR_REQUIRE_DATA();
  const auto files = test::data_files("bvh", ".bvh");
  ASSERT_GE(files.size(), 30u);
  for (const auto& path : files) {
    SCOPED_TRACE(path.string());
    Warnings w;
    auto r = read_bvh(path, &w);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
    const Motion& m = *r;
    EXPECT_TRUE(m.validate().ok());
    EXPECT_GT(m.frame_count, 0u);
    EXPECT_GT(m.skeleton.size(), 0u);
    for (const Error& e : w) EXPECT_GT(e.line, 0) << e.to_string();

    const std::string text = format_bvh(m).value();
    auto back = parse_bvh(text, "written");
    ASSERT_TRUE(back.ok()) << back.error().to_string();
    EXPECT_EQ(back->values, m.values);
    EXPECT_EQ(back->frame_time, m.frame_time);
    ASSERT_EQ(back->skeleton.size(), m.skeleton.size());
    for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
      EXPECT_EQ(back->skeleton.joint(j).name, m.skeleton.joint(j).name);
      EXPECT_EQ(back->skeleton.joint(j).parent, m.skeleton.joint(j).parent);
      EXPECT_EQ(back->skeleton.joint(j).offset, m.skeleton.joint(j).offset);
      EXPECT_EQ(back->skeleton.joint(j).channels, m.skeleton.joint(j).channels);
    }
    // Positions, from the original and from the re-read file (every frame in
    // Release; the values above are compared for every frame in all builds).
    const auto pa = compute_positions(test::sample_frames(m));
    const auto pb = compute_positions(test::sample_frames(*back));
    EXPECT_POSITIONS_NEAR(m.skeleton, pa, pb, 0.0);
  }
}

TEST(BvhRealFiles, KnownShapes) {
  GMR_REQUIRE_DATA();
  const Motion cmu = read_bvh(test::data_file("bvh/cmu/02_01.bvh")).value();  // mixed CRLF / LF
  EXPECT_EQ(cmu.skeleton.size(), 38u);                                        // 31 joints + 7 End Sites
  EXPECT_EQ(cmu.stride(), 96u);
  EXPECT_EQ(cmu.frame_count, 344u);
  EXPECT_EQ(cmu.frame_time, 0.0083333);
  EXPECT_EQ(cmu.values[0], 10.4194);  // PROVENANCE: first root position (10.4194, 16.7048, -30.1003)
  EXPECT_EQ(cmu.values[1], 16.7048);
  EXPECT_EQ(cmu.values[2], -30.1003);

  const Motion warrok = read_bvh(test::data_file("bvh/mixamo/WarrokRun_noEndSite.bvh")).value();
  // No End Site blocks: its leaves (HeadTop_End, ...) are JOINTs with channels.
  for (const Joint& j : warrok.skeleton.joints()) EXPECT_FALSE(j.channels.empty()) << j.name;

  const Motion rot_first = read_bvh(test::data_file("bvh/parser_fixtures/pybvh_rotation_first_root.bvh")).value();
  EXPECT_EQ(rot_first.skeleton.joint(0).channels[0], ChannelType::kZrotation);
  EXPECT_EQ(rot_first.skeleton.joint(0).channels[3], ChannelType::kXposition);

  const Motion anim = read_bvh(test::data_file("bvh/parser_fixtures/bvh_anim_test_simple.bvh")).value();
  ASSERT_EQ(anim.skeleton.size(), 3u);
  EXPECT_EQ(anim.skeleton.joint(1).name, "End");  // a joint named End is a joint
  EXPECT_EQ(anim.skeleton.joint(2).name, "End_End");
}

// The malformed corpus, file by file. Decisions:
// - a frame count that does not match complete rows: load every complete row, warn;
// - a file that ends inside a frame, or has no rows though Frames > 0: error
//   (truncated; loading part of a take silently is worse than stopping);
// - blank lines anywhere between tokens: fine, no warning.
TEST(BvhRealFiles, MalformedCorpus) {
  GMR_REQUIRE_DATA();
  {
    Warnings w;
    const Motion m = read_bvh(test::data_file("malformed/Boxing_Toes_frames_off_by_one.bvh"), &w).value();
    EXPECT_EQ(m.frame_count, 3070u);
    ASSERT_EQ(w.size(), 1u);
    EXPECT_EQ(w[0].line, 128);
    EXPECT_THAT(w[0].message, HasSubstr("'Frames: 3069' but the file holds 3070"));
  }
  for (const char* name : {"malformed/bvhio_example_blankline.bvh", "malformed/milad_blankline_6ch_joints.bvh"}) {
    Warnings w;
    auto r = read_bvh(test::data_file(name), &w);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
    EXPECT_TRUE(w.empty()) << name;
  }
  EXPECT_EQ(read_bvh(test::data_file("malformed/milad_blankline_6ch_joints.bvh"))->frame_count, 422u);
  EXPECT_EQ(read_bvh(test::data_file("malformed/bvhio_example_blankline.bvh"))->frame_count, 2u);

  struct Broken {
    const char* file;
    const char* message;
  };
  for (const Broken& b : {Broken{"malformed/TRUNC_02_01_in_hierarchy.bvh", "found end of file"},
                          Broken{"malformed/TRUNC_02_01_mid_frame.bvh", "file ends in frame 129"},
                          Broken{"malformed/TRUNC_02_01_no_motion_lines.bvh", "no frame data"},
                          Broken{"malformed/bvhio_header_only_frames3066.bvh", "no frame data"}}) {
    const auto path = test::data_file(b.file);
    auto r = read_bvh(path);
    ASSERT_FALSE(r.ok()) << b.file;
    EXPECT_EQ(r.error().file, path.string());
    EXPECT_GT(r.error().line, 0);
    EXPECT_GT(r.error().column, 0);
    EXPECT_THAT(r.error().message, HasSubstr(b.message));
    EXPECT_THAT(r.error().to_string(), HasSubstr(path.string() + ":" + std::to_string(r.error().line) + ":"));
  }
}

TEST(BvhRealFiles, EveryMalformedBvhLoadsOrGivesALocatedError) {
  GMR_REQUIRE_DATA();
  for (const auto& path : test::data_files("malformed", ".bvh")) {
    Warnings w;
    auto r = read_bvh(path, &w);
    if (!r.ok()) {
      EXPECT_GT(r.error().line, 0) << r.error().to_string();
    } else {
      EXPECT_TRUE(r->validate().ok()) << path;
    }
  }
}

}  // namespace
}  // namespace gmr
