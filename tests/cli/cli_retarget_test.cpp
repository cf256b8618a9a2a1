// gmr retarget and gmr info --humanoid: the command writes the rig's skeleton
// with the source's frames (atomically, by extension), reports what it found,
// takes --map files, and refuses bad maps and rigs in one located line.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <string>

#include "cli_test_util.h"
#include "gmr/core/file_util.h"
#include "gmr/io/motion_file.h"
#include "test_data.h"

namespace gmr {
namespace {
using test::shell_quote;
using ::testing::HasSubstr;

class CliRetarget : public test::CliTest {};

TEST_F(CliRetarget, PutsATakeOnARigAndSaysWhatItMapped) {
  GMR_REQUIRE_DATA();
  const std::string source = shell_quote(test::data_file("asfamc/02/02_01.amc").string());
  const std::string rig = shell_quote(test::data_file("bvh/mixamo/Beta_jump.bvh").string());
  const auto info = gmr("info " + rig + " --humanoid");
  ASSERT_EQ(info.status, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("humanoid:    mixamo naming"));
  EXPECT_THAT(info.out, HasSubstr("left_lower_arm   Beta:LeftForeArm"));
  for (const char* out : {"walk.bvh", "walk.gmr", "walk.gmrb"}) {
    SCOPED_TRACE(out);
    const auto r = gmr("retarget " + source + " " + path(out) + " --target " + rig);
    ASSERT_EQ(r.status, 0) << r.err;
    EXPECT_THAT(r.err, HasSubstr("retargeted 343 frames"));
    EXPECT_THAT(r.err, HasSubstr("cmu-asf naming"));
    auto m = load_motion(dir_ / out);
    ASSERT_TRUE(m.ok()) << m.error().to_string();
    EXPECT_EQ(m->frame_count, 343u);
    auto rig_motion = load_motion(test::data_file("bvh/mixamo/Beta_jump.bvh"));
    ASSERT_TRUE(rig_motion.ok());
    ASSERT_EQ(m->skeleton.size(), rig_motion->skeleton.size());
    for (int j = 0; j < static_cast<int>(m->skeleton.size()); ++j) {
      EXPECT_EQ(m->skeleton.joint(j).name, rig_motion->skeleton.joint(j).name);
    }
  }
  // A --map that says what the built-in naming says gives the same file.
  ASSERT_TRUE(write_file_atomic(dir_ / "map.json",
                                R"({"hips": "Beta:Hips", "head": "Beta:Head", "left_upper_arm": "Beta:LeftArm",
                                    "left_lower_arm": "Beta:LeftForeArm", "left_hand": "Beta:LeftHand",
                                    "right_upper_arm": "Beta:RightArm", "right_lower_arm": "Beta:RightForeArm",
                                    "right_hand": "Beta:RightHand", "left_upper_leg": "Beta:LeftUpLeg",
                                    "left_lower_leg": "Beta:LeftLeg", "left_foot": "Beta:LeftFoot",
                                    "right_upper_leg": "Beta:RightUpLeg", "right_lower_leg": "Beta:RightLeg",
                                    "right_foot": "Beta:RightFoot"})")
                  .ok());
  const auto mapped =
      gmr("retarget " + source + " " + path("mapped.bvh") + " --target " + rig + " --map " + path("map.json"));
  ASSERT_EQ(mapped.status, 0) << mapped.err;
  EXPECT_THAT(mapped.err, HasSubstr("(map naming"));
}

TEST_F(CliRetarget, BadMapsAndRigsGiveOneLine) {
  GMR_REQUIRE_DATA();
  const std::string source = shell_quote(test::data_file("asfamc/02/02_01.amc").string());
  const std::string rig = shell_quote(test::data_file("bvh/mixamo/Beta_jump.bvh").string());
  ASSERT_TRUE(write_file_atomic(dir_ / "broken.json", "{\"hips\": ").ok());
  expect_one_line_error(
      "retarget " + source + " " + path("o.bvh") + " --target " + rig + " --map " + path("broken.json"),
      "not a JSON object of role -> joint name");
  ASSERT_TRUE(write_file_atomic(dir_ / "absent.json", "{\"hips\": \"Pelvis\"}").ok());
  expect_one_line_error(
      "retarget " + source + " " + path("o.bvh") + " --target " + rig + " --map " + path("absent.json"),
      "gives role 'hips' to 'Pelvis', which the skeleton does not have");
  const std::string crab = shell_quote(test::data_file("bvh/truebones/Crab-dance-long.bvh").string());
  expect_one_line_error("retarget " + source + " " + path("o.bvh") + " --target " + crab, "not a humanoid");
  expect_one_line_error("info " + crab + " --humanoid", "not a humanoid");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "o.bvh")) << "nothing written on a refusal";
}

// --keep-contacts: the same take with its resting feet pinned, and the command
// says how many contacts it kept and how far the ankles slid before and after.
TEST_F(CliRetarget, KeepContactsPinsTheFeetAndSaysSo) {
  GMR_REQUIRE_DATA();
  const std::string source = shell_quote(test::data_file("bvh/cmu/02_01.bvh").string());
  const std::string rig = shell_quote(test::data_file("bvh/mixamo/Beta_jump.bvh").string());
  const auto plain = gmr("retarget " + source + " " + path("plain.bvh") + " --target " + rig);
  ASSERT_EQ(plain.status, 0) << plain.err;
  EXPECT_THAT(plain.err, ::testing::Not(HasSubstr("contacts")));
  const auto kept = gmr("retarget " + source + " " + path("kept.bvh") + " --target " + rig + " --keep-contacts");
  ASSERT_EQ(kept.status, 0) << kept.err;
  EXPECT_THAT(kept.err, HasSubstr("feet kept on the floor: "));
  EXPECT_THAT(kept.err, HasSubstr("the farthest a resting ankle slid: "));
  auto a = load_motion(dir_ / "plain.bvh");
  auto b = load_motion(dir_ / "kept.bvh");
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->frame_count, b->frame_count);
  EXPECT_NE(a->values, b->values) << "--keep-contacts changed nothing";
}

}  // namespace
}  // namespace gmr
