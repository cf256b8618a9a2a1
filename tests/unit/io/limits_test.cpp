// One limit for every reader (gmr/core/limits.h, docs/gmr-format.md
// "Limits"): a declared frame count that the file's bytes cannot back is an
// error that says where, frames without data are capped at 2^20, and no
// reader takes more than 2^24 frames.
#include "gmr/core/limits.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstring>

#include "gmr/io/bvh.h"
#include "gmr/io/gmr_file.h"
#include "gmr/io/gmrb.h"

namespace gmr {
namespace {
using ::testing::HasSubstr;

TEST(FrameLimits, TheRule) {
  EXPECT_TRUE(check_frame_count(kMaxEmptyFrames, 0).ok());
  EXPECT_THAT(check_frame_count(kMaxEmptyFrames + 1, 0).error().message,
              HasSubstr("frame count 1048577 is above gmr's limit of 1048576 for frames that carry no data"));
  EXPECT_TRUE(check_frame_count(kMaxFrames, 8).ok());
  EXPECT_THAT(check_frame_count(kMaxFrames + 1, 8).error().message,
              HasSubstr("frame count 16777217 is above gmr's limit of 16777216 frames per file"));
  EXPECT_TRUE(check_frame_count(10, 8, 80).ok());
  EXPECT_EQ(check_frame_count(11, 8, 80).error().message,
            "frame count 11 needs 8 bytes per frame, but the file holds only 80 bytes for them");
  EXPECT_EQ(check_frame_count(UINT64_MAX, 8, 80).error().kind, ErrorKind::kInvalidData);
}

// One joint without channels: a 76-byte BVH whose only content is its frame count.
std::string channel_less(std::string_view magic, std::string_view frames) {
  return std::string(magic) +
         "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n CHANNELS 0\n}\nMOTION\nFrames: " + std::string(frames) +
         "\nFrame Time: 0.01\n";
}

TEST(FrameLimits, TextFramesWithoutChannelsAreCapped) {
  for (std::string_view magic : {"", "GMR 1\n"}) {
    SCOPED_TRACE(magic);
    const auto parse = [&](std::string_view frames) {
      const std::string text = channel_less(magic, frames);
      return magic.empty() ? parse_bvh(text, "x") : parse_gmr(text, "x");
    };
    auto ok = parse("1048576");
    ASSERT_TRUE(ok.ok()) << ok.error().to_string();
    EXPECT_EQ(ok->frame_count, kMaxEmptyFrames);
    EXPECT_TRUE(ok->values.empty());
    auto over = parse("1048577");
    ASSERT_FALSE(over.ok());
    EXPECT_EQ(over.error().line, magic.empty() ? 8 : 9) << over.error().to_string();
    EXPECT_THAT(over.error().message, HasSubstr("for frames that carry no data")) << over.error().to_string();
    EXPECT_FALSE(parse("18446744073709551615").ok());
  }
}

TEST(FrameLimits, GmrbFrameCountsAreCheckedAgainstTheLimit) {
  // A .gmrb of one joint without channels whose header claims `frames`
  // (the u64 at byte 40; no data bytes are needed for such frames).
  Motion m;
  Joint a;
  a.name = "A";
  m.skeleton = Skeleton::create({a}).value();
  m.frame_count = 3;
  m.frame_time = 0.01;
  const std::string good = format_gmrb(m).value();
  const auto with_frames = [&](std::uint64_t frames) {
    std::string b = good;
    for (int i = 0; i < 8; ++i) b[40 + static_cast<std::size_t>(i)] = static_cast<char>(frames >> (8 * i));
    return b;
  };
  ASSERT_EQ(parse_gmrb(with_frames(3), "x.gmrb")->frame_count, 3u);
  EXPECT_EQ(parse_gmrb(with_frames(kMaxEmptyFrames), "x.gmrb")->frame_count, kMaxEmptyFrames);
  for (std::uint64_t frames : {kMaxEmptyFrames + 1, std::uint64_t{1} << 40}) {
    auto r = parse_gmrb(with_frames(frames), "x.gmrb");
    ASSERT_FALSE(r.ok()) << frames;
    EXPECT_THAT(r.error().to_string(),
                HasSubstr("x.gmrb: at byte 40: frame count " + std::to_string(frames) + " is above gmr's limit of "));
  }
}

}  // namespace
}  // namespace gmr
