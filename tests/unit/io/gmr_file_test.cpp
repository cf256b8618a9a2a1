// The GMR text format (docs/gmr-format.md): reader, writer, exact round trip.
#include "gmr/io/gmr_file.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

#include "gmr/io/bvh.h"
#include "gmr/core/file_util.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "io_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {

using ::testing::HasSubstr;

// The example of docs/gmr-format.md: two trees, the second split off the
// first (soft link), a root without rotation, a joint without channels.
constexpr std::string_view kExample =
    "GMR 1\n"
    "HIERARCHY\n"
    "ROOT Hips\n"
    "{\n"
    "\tOFFSET 0 0 0\n"
    "\tCHANNELS 3 Xposition Yposition Zposition\n"
    "\tJOINT Spine\n"
    "\t{\n"
    "\t\tOFFSET 0 10 0\n"
    "\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n"
    "\t}\n"
    "\tJOINT LeftUpLeg\n"
    "\t{\n"
    "\t\tOFFSET 2 -1 0\n"
    "\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n"
    "\t\tJOINT LeftLeg\n"
    "\t\t{\n"
    "\t\t\tOFFSET 0 -9 0\n"
    "\t\t\tCHANNELS 1 Xrotation\n"
    "\t\t}\n"
    "\t}\n"
    "}\n"
    "ROOT Neck\n"
    "{\n"
    "\tSOFTLINK Spine\n"
    "\tOFFSET 0 0 0\n"
    "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
    "\tJOINT Head\n"
    "\t{\n"
    "\t\tOFFSET 0 3 0\n"
    "\t\tCHANNELS 0\n"
    "\t}\n"
    "}\n"
    "MOTION\n"
    "Frames: 2\n"
    "Frame Time: 0.033333333333333333\n"
    "0 90 0 90 0 0 0 0 0 30 0 0 0 20 0 0\n"
    "1 90 0 80 0 10 0 0 0 -30 0 0 0 20 0 0\n";

Motion parse_ok(std::string_view text, Warnings* w = nullptr) {
  auto r = parse_gmr(text, "test.gmr", w);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().to_string());
  return r.ok() ? std::move(r).value() : Motion{};
}

Error parse_error(std::string_view text) {
  auto r = parse_gmr(text, "test.gmr");
  EXPECT_FALSE(r.ok());
  if (r.ok()) return Error{};
  EXPECT_GT(r.error().line, 0);
  return r.error();
}

std::string replace(std::string s, std::string_view from, std::string_view to) {
  const auto p = s.find(from);
  EXPECT_NE(p, std::string::npos) << from;
  if (p != std::string::npos) s.replace(p, from.size(), to);
  return s;
}

TEST(GmrFormat, ReadsTheDocumentedExample) {
  Warnings w;
  const Motion m = parse_ok(kExample, &w);
  EXPECT_TRUE(w.empty());
  EXPECT_EQ(m.convention, Convention::kPreRotation);
  ASSERT_EQ(m.skeleton.size(), 6u);
  ASSERT_EQ(m.skeleton.roots().size(), 2u);
  const int neck = m.skeleton.find("Neck");
  EXPECT_EQ(m.skeleton.joint(neck).soft_parent, m.skeleton.find("Spine"));
  EXPECT_TRUE(m.skeleton.joint(0).channels.size() == 3 && !m.skeleton.joint(0).has_rotation());
  EXPECT_EQ(m.frame_count, 2u);
  EXPECT_EQ(m.frame_time, 1.0 / 30.0);

  // Pre-rotation: Spine's 90 degrees about Z turn the bone Hips->Spine itself.
  std::vector<Eigen::Vector3d> p(6);
  compute_frame(m, 0, p);
  EXPECT_TRUE(p[1].isApprox(Eigen::Vector3d(-10, 90, 0), 1e-12));
  // LeftLeg's 30 degrees about X move LeftLeg (pre-rotation), not only its children.
  const Eigen::Vector3d knee =
      Eigen::Vector3d(0, 90, 0) + Eigen::Vector3d(2, -1, 0) + axis_rotation(Axis::kX, 30) * Eigen::Vector3d(0, -9, 0);
  EXPECT_TRUE(p[3].isApprox(knee, 1e-12));
  // Neck is a root: world = [R | t], t its position channels.
  EXPECT_TRUE(p[4].isApprox(Eigen::Vector3d(0, 0, 0), 1e-12));
  EXPECT_TRUE(p[5].isApprox(axis_rotation(Axis::kZ, 20) * Eigen::Vector3d(0, 3, 0), 1e-12));
}

// docs/gmr-format.md shows the same example: keep the two in step.
TEST(GmrFormat, DocumentationExampleIsThisOne) {
  const char* src = std::getenv("GMR_SOURCE_DIR");
  const std::filesystem::path doc = std::filesystem::path(src != nullptr ? src : ".") / "docs" / "gmr-format.md";
  auto text = read_file(doc);
  ASSERT_TRUE(text.ok()) << text.error().to_string();
  const auto begin = text->find("```\nGMR 1\n");
  ASSERT_NE(begin, std::string::npos);
  const auto end = text->find("```", begin + 3);
  ASSERT_NE(end, std::string::npos);
  const Motion from_doc = parse_ok(std::string_view(*text).substr(begin + 4, end - begin - 4));
  const Motion here = parse_ok(kExample);
  EXPECT_EQ(from_doc.values, here.values);
  EXPECT_EQ(from_doc.frame_time, here.frame_time);
  EXPECT_EQ(format_gmr(from_doc).value(), format_gmr(here).value());
}

TEST(GmrFormat, WriteReadIsExact) {
  Motion m = parse_ok(kExample);
  m.values[3] = 0.1 + 0.2;
  m.values[4] = 1.0 / 3.0;
  const std::string text = format_gmr(m).value();
  EXPECT_EQ(text.rfind("GMR 1\nHIERARCHY\n", 0), 0u);
  const Motion back = parse_ok(text);
  EXPECT_EQ(back.values, m.values);
  EXPECT_EQ(back.frame_time, m.frame_time);
  ASSERT_EQ(back.skeleton.size(), m.skeleton.size());
  for (int j = 0; j < static_cast<int>(m.skeleton.size()); ++j) {
    const Joint& a = m.skeleton.joint(j);
    const Joint& b = back.skeleton.joint(j);
    EXPECT_EQ(a.name, b.name);
    EXPECT_EQ(a.parent, b.parent);
    EXPECT_EQ(a.soft_parent, b.soft_parent);
    EXPECT_EQ(a.offset, b.offset);
    EXPECT_EQ(a.channels, b.channels);
  }
  EXPECT_EQ(format_gmr(back).value(), text);
}

TEST(GmrFormat, NonDepthFirstJointOrderKeepsPositionsPerName) {
  // Operations may leave joints parents-first but not depth-first: move Neck's
  // tree to the front and interleave the rest.
  const Motion m = parse_ok(kExample);
  const std::vector<int> order = {4, 0, 5, 2, 1, 3};  // Neck Hips Head LeftUpLeg Spine LeftLeg
  std::vector<int> new_index(6);
  for (int i = 0; i < 6; ++i) new_index[order[i]] = i;
  std::vector<Joint> joints;
  for (int old : order) {
    Joint j = m.skeleton.joint(old);
    if (j.parent != kNoParent) j.parent = new_index[j.parent];
    if (j.soft_parent != kNoParent) j.soft_parent = new_index[j.soft_parent];
    joints.push_back(j);
  }
  Motion shuffled;
  shuffled.skeleton = Skeleton::create(joints).value();
  shuffled.convention = Convention::kPreRotation;
  shuffled.frame_time = m.frame_time;
  shuffled.frame_count = m.frame_count;
  for (std::size_t f = 0; f < m.frame_count; ++f)
    for (int old : order)
      for (double v : m.joint_values(f, old)) shuffled.values.push_back(v);

  const Motion back = parse_ok(format_gmr(shuffled).value());
  const auto ps = compute_positions(shuffled);
  const auto pb = compute_positions(back);
  for (int j = 0; j < 6; ++j) {
    const int k = back.skeleton.find(shuffled.skeleton.joint(j).name);
    ASSERT_GE(k, 0);
    EXPECT_EQ(back.skeleton.joint(k).soft_parent == kNoParent, shuffled.skeleton.joint(j).soft_parent == kNoParent);
    for (std::size_t f = 0; f < 2; ++f) EXPECT_EQ(ps[f * 6 + j], pb[f * 6 + k]) << shuffled.skeleton.joint(j).name;
  }
}

TEST(GmrFormat, VersionLine) {
  EXPECT_THAT(parse_error(replace(std::string(kExample), "GMR 1", "GMR 2")).message,
              HasSubstr("unsupported GMR format version 2"));
  EXPECT_THAT(parse_error(replace(std::string(kExample), "GMR 1\n", "")).message,
              HasSubstr("expected the format line 'GMR 1', found 'HIERARCHY'"));
  EXPECT_THAT(parse_error(replace(std::string(kExample), "GMR 1", "GMR one")).message, HasSubstr("format version"));
}

TEST(GmrFormat, SoftLinkErrors) {
  EXPECT_THAT(parse_error(replace(std::string(kExample), "SOFTLINK Spine", "SOFTLINK Nobody")).message,
              HasSubstr("unknown joint 'Nobody'"));
  EXPECT_THAT(parse_error(replace(std::string(kExample), "SOFTLINK Spine", "SOFTLINK Neck")).message,
              HasSubstr("itself"));
  EXPECT_THAT(parse_error(replace(std::string(kExample), "\t\tCHANNELS 0\n", "\t\tSOFTLINK Hips\n")).message,
              HasSubstr("ROOT only"));
  EXPECT_THAT(
      parse_error(replace(std::string(kExample), "\tSOFTLINK Spine\n", "\tSOFTLINK Spine\n\tSOFTLINK Hips\n")).message,
      HasSubstr("second SOFTLINK"));
}

TEST(GmrFormat, BvhOnlySyntaxIsRejected) {
  const Error e = parse_error(replace(std::string(kExample), "\tJOINT Head", "\tEnd Site"));
  EXPECT_EQ(e.line, 28);
  EXPECT_THAT(e.message, HasSubstr("expected OFFSET, CHANNELS, SOFTLINK, JOINT or '}'"));
}

TEST(GmrFormat, SameDataErrorsAsBvh) {
  EXPECT_THAT(parse_error(replace(std::string(kExample), "0 90 0 90", "0 90 0-90")).message, HasSubstr("run together"));
  EXPECT_THAT(parse_error(kExample.substr(0, kExample.size() - 5)).message, HasSubstr("file ends in frame 1"));
}

TEST(GmrFormat, WriterRefusesPostRotation) {
  Motion m = parse_ok(kExample);
  m.convention = Convention::kPostRotation;
  EXPECT_THAT(format_gmr(m).error().message, HasSubstr("pre-rotation"));
}

// Every BVH of the corpus, taken as a pre-rotation motion (the same numbers;
// what they mean does not matter to the file format), survives .gmr exactly.
TEST(GmrFormatRealFiles, EveryBvhRoundTripsThroughGmrText) {
  GMR_REQUIRE_DATA();
  for (const auto& path : test::data_files("bvh", ".bvh")) {
    SCOPED_TRACE(path.string());
    auto r = read_bvh(path);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
    Motion m = std::move(r).value();
    m.convention = Convention::kPreRotation;
    const std::string text = format_gmr(m).value();
    auto back = parse_gmr(text, "written.gmr");
    ASSERT_TRUE(back.ok()) << back.error().to_string();
    EXPECT_EQ(back->values, m.values);
    EXPECT_EQ(back->frame_time, m.frame_time);
    const auto pa = compute_positions(test::sample_frames(m));
    const auto pb = compute_positions(test::sample_frames(*back));
    EXPECT_POSITIONS_NEAR(m.skeleton, pa, pb, 0.0);
  }
}

}  // namespace
}  // namespace gmr
