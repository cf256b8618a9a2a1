// Marker files in the `gmr` command: info, markers (CSV), convert to .trc,
// and the one-line errors.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include "cli_test_util.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "test_data.h"

namespace gmr {
namespace {
using ::testing::HasSubstr;
using ::testing::StartsWith;
using test::shell_quote;

class CliMarkers : public test::CliTest {};

std::size_t lines(const std::string& s) { return static_cast<std::size_t>(std::count(s.begin(), s.end(), '\n')); }

TEST_F(CliMarkers, InfoSummarisesC3dAndTrc) {
  GMR_REQUIRE_DATA();
  const auto c3d = gmr("info " + shell_quote(test::data_file("c3d/cmu_02_01.c3d").string()));
  ASSERT_EQ(c3d.status, 0) << c3d.err;
  EXPECT_THAT(c3d.out, HasSubstr("markers:     41\nframes:      343\nfirst frame: 50\nframe rate:  120 Hz\nunits:       mm\n"
                                 "missing:     0 of 14063 points (0.0%)\n"));
  EXPECT_THAT(c3d.out, HasSubstr(" TakeoMonday:LFWT "));
  EXPECT_TRUE(c3d.err.empty()) << c3d.err;

  const auto vicon = gmr("info " + shell_quote(test::data_file("c3d/vicon_markers_analogs.c3d").string()));
  EXPECT_THAT(vicon.out, HasSubstr("analog:      38 channels at 2000 Hz (not loaded)\n"));

  const auto trc = gmr("info " + shell_quote(test::data_file("trc/opensim_walk_free_01.trc").string()));
  ASSERT_EQ(trc.status, 0) << trc.err;
  EXPECT_THAT(trc.out, HasSubstr("frames:      73\nfirst frame: 185\nframe rate:  60 Hz\n"));
  // The header's NumFrames 900 is a warning after the output.
  EXPECT_THAT(trc.err, StartsWith("gmr: warning: "));
  EXPECT_THAT(trc.err, HasSubstr(":3:20: NumFrames is 900 but the file holds 73 rows"));
}

TEST_F(CliMarkers, MarkersCsvWithMissingPointsAsEmptyCells) {
  GMR_REQUIRE_DATA();
  const std::string file = shell_quote(test::data_file("trc/edge/exampleFormat_missing_and_nan.trc").string());
  const auto all = gmr("markers " + file);
  ASSERT_EQ(all.status, 0) << all.err;
  EXPECT_THAT(all.out, StartsWith("frame,marker,x,y,z\n0,marker1,,,\n0,marker2,-0.152,0.245,-1.71\n"));
  EXPECT_THAT(all.out, HasSubstr("\n2,marker2,,,\n"));
  EXPECT_EQ(lines(all.out), 1 + 5u * 3u);

  const auto some = gmr("markers " + file + " --frames 1:3");
  ASSERT_EQ(some.status, 0) << some.err;
  EXPECT_EQ(lines(some.out), 1 + 2u * 3u);
  EXPECT_THAT(some.out, StartsWith("frame,marker,x,y,z\n1,marker1,-0.273,0.0745,-1.57\n"));

  const auto c3d = gmr("markers " + shell_quote(test::data_file("c3d/cmu_02_01.c3d").string()) + " --frames :1");
  ASSERT_EQ(c3d.status, 0) << c3d.err;
  EXPECT_EQ(lines(c3d.out), 1 + 41u);
  EXPECT_THAT(c3d.out, HasSubstr("\n0,TakeoMonday:LFWT,"));
}

TEST_F(CliMarkers, ConvertC3dToTrcAndTrcToTrc) {
  GMR_REQUIRE_DATA();
  const std::string in = test::data_file("c3d/opensim_walking2.c3d").string();
  const auto r = gmr("convert " + shell_quote(in) + " " + path("w.TRC"));
  ASSERT_EQ(r.status, 0) << r.err;
  auto a = read_c3d(in);
  auto b = read_trc(dir_ / "w.TRC");
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->names, b->names);
  ASSERT_EQ(a->positions.size(), b->positions.size());
  for (std::size_t i = 0; i < a->positions.size(); ++i) {
    ASSERT_TRUE(a->positions[i] == b->positions[i] || (std::isnan(a->positions[i]) && std::isnan(b->positions[i]))) << i;
  }
  const auto again = gmr("convert " + path("w.TRC") + " " + path("w2.trc"));
  ASSERT_EQ(again.status, 0) << again.err;
  EXPECT_EQ(read_trc(dir_ / "w2.trc")->frame_count, 1249u);
}

TEST_F(CliMarkers, OneLineErrors) {
  GMR_REQUIRE_DATA();
  const std::string trunc = test::data_file("malformed/TRUNC_opensim_walk_free_01_mid_row.trc").string();
  for (const char* cmd : {"info", "markers"}) {
    expect_one_line_error(std::string(cmd) + " " + shell_quote(trunc),
                          trunc + ":35:689: file ends after 64 of 125 values");
  }
  const std::string params = test::data_file("malformed/TRUNC_cmu_02_01_in_parameters.c3d").string();
  expect_one_line_error("markers " + shell_quote(params), params + ": at byte ");
  expect_one_line_error("convert " + shell_quote(test::data_file("c3d/cmu_02_01.c3d").string()) + " " + path("x.bvh"),
                        "cannot write markers as '.bvh': expected .trc");
  expect_one_line_error("markers " + path("none.bvh"), "cannot load '.bvh' files as markers: expected .c3d or .trc");
  expect_one_line_error("markers " + shell_quote(trunc) + " --frames 5:2", "gmr: ");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "x.bvh"));  // nothing written by the failed convert
}

}  // namespace
}  // namespace gmr
