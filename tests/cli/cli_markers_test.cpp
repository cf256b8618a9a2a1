// Marker files in the `gmr` command: info, markers (CSV), convert to .trc,
// and the one-line errors.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include "cli_test_util.h"
#include "gmr/core/file_util.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "test_data.h"

namespace gmr {
namespace {
using test::shell_quote;
using ::testing::HasSubstr;
using ::testing::StartsWith;

class CliMarkers : public test::CliTest {};

std::size_t lines(const std::string& s) { return static_cast<std::size_t>(std::count(s.begin(), s.end(), '\n')); }

TEST_F(CliMarkers, InfoSummarisesC3dAndTrc) {
  GMR_REQUIRE_DATA();
  const auto c3d = gmr("info " + shell_quote(test::data_file("c3d/cmu_02_01.c3d").string()));
  ASSERT_EQ(c3d.status, 0) << c3d.err;
  EXPECT_THAT(c3d.out,
              HasSubstr("markers:     41\nframes:      343\nfirst frame: 50\nframe rate:  120 Hz\nunits:       mm\n"
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
    ASSERT_TRUE(a->positions[i] == b->positions[i] || (std::isnan(a->positions[i]) && std::isnan(b->positions[i])))
        << i;
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
                        "markers become a motion through a skeleton model: add --model NAME or --model FILE "
                        "(built in: cmu41), or write .trc");
  expect_one_line_error(
      "convert " + shell_quote(test::data_file("c3d/cmu_02_01.c3d").string()) + " " + path("x.bvh") + " --model cmu99",
      "'cmu99' is neither a built-in marker model (cmu41) nor a file");
  expect_one_line_error(
      "convert " + shell_quote(test::data_file("c3d/cmu_02_01.c3d").string()) + " " + path("x.trc") + " --model cmu41",
      "a .trc output keeps the markers");
  // A take without the CMU markers: the model names what is missing.
  expect_one_line_error("convert " + shell_quote(test::data_file("c3d/opensim_walking2.c3d").string()) + " " +
                            path("x.bvh") + " --model cmu41",
                        "the marker file lacks ");
  expect_one_line_error("markers " + path("none.bvh"), "cannot load '.bvh' files as markers: expected .c3d or .trc");
  expect_one_line_error("markers " + shell_quote(trunc) + " --frames 5:2", "gmr: ");
  EXPECT_FALSE(std::filesystem::exists(dir_ / "x.bvh"));  // nothing written by the failed convert
}

// Markers -> motion: convert with the built-in CMU model to every motion
// format, positions read back from the file equal the library's solve, the
// roots move, and info reports the fit.
TEST_F(CliMarkers, ConvertWithAModelWritesAMotionAndInfoReportsTheFit) {
  GMR_REQUIRE_DATA();
  const std::string c3d = shell_quote(test::data_file("c3d/cmu_02_01.c3d").string());
  const auto conv = gmr("convert " + c3d + " " + path("walk.gmr") + " --model cmu41");
  ASSERT_EQ(conv.status, 0) << conv.err;
  const auto pos = gmr("positions " + path("walk.gmr") + " --frames 100:101");
  ASSERT_EQ(pos.status, 0) << pos.err;
  EXPECT_THAT(pos.out, HasSubstr("\n100,lfemur,"));
  EXPECT_EQ(lines(pos.out), 1 + 21u);  // the 21 joints of cmu41
  // gmr positions solves the markers itself: the same rows as the file it wrote.
  const auto direct = gmr("positions " + c3d + " --model cmu41 --frames 100:101");
  ASSERT_EQ(direct.status, 0) << direct.err;
  EXPECT_EQ(direct.out, pos.out);
  expect_one_line_error("positions " + c3d, "a marker file gives joint positions through a skeleton model");

  // Another set of roots: the same positions, to print precision.
  const auto rooted = gmr("convert " + c3d + " " + path("walk2.gmr") + " --model cmu41 --roots lfemur,head");
  ASSERT_EQ(rooted.status, 0) << rooted.err;
  const auto info = gmr("info " + path("walk2.gmr"));
  EXPECT_THAT(info.out, HasSubstr("lfemur, head"));
  const auto pos2 = gmr("positions " + path("walk2.gmr") + " --frames 100:101");
  ASSERT_EQ(pos2.status, 0) << pos2.err;
  EXPECT_EQ(lines(pos2.out), lines(pos.out));

  for (const char* ext : {"bvh", "gmrb"}) {
    const auto r = gmr("convert " + c3d + " " + path(std::string("walk.") + ext) + " --model cmu41");
    EXPECT_EQ(r.status, 0) << ext << ": " << r.err;
  }

  // A model file beside the data: `builtin cmu41`.
  ASSERT_TRUE(write_file_atomic(dir_ / "cmu.model", "builtin cmu41\n").ok());
  const auto report = gmr("info " + c3d + " --model " + path("cmu.model"));
  ASSERT_EQ(report.status, 0) << report.err;
  EXPECT_THAT(report.out, HasSubstr("model:       "));
  EXPECT_THAT(report.out, HasSubstr("\nlthigh "));
  EXPECT_THAT(report.out, HasSubstr("\nlfemur      centre "));
  EXPECT_THAT(report.out, HasSubstr("motion rms"));
  expect_one_line_error("info " + path("walk.gmr") + " --model cmu41", "--model applies to marker files");
  expect_one_line_error("convert " + path("walk.gmr") + " " + path("w.bvh") + " --roots head",
                        "--model and --roots apply to marker files");
  expect_one_line_error("convert " + c3d + " " + path("w.bvh") + " --model cmu41 --roots nose", "unknown joint 'nose'");
}

// --calibrate-seconds: each frame solved alone, as a live marker source is,
// on a calibration of the first seconds; what it did goes to stderr. Another
// solve than the whole take's, of the same joints, near it.
TEST_F(CliMarkers, ConvertFrameByFrameOnACalibrationOfTheFirstSeconds) {
  GMR_REQUIRE_DATA();
  const std::string c3d = shell_quote(test::data_file("c3d/cmu_02_01.c3d").string());
  const auto frames = gmr("convert " + c3d + " " + path("live.gmr") + " --model cmu41 --calibrate-seconds 2");
  ASSERT_EQ(frames.status, 0) << frames.err;
  EXPECT_THAT(frames.err, HasSubstr("calibrated on frames 0-239; solved 343 frames one at a time (0 refused"));
  const auto whole = gmr("convert " + c3d + " " + path("whole.gmr") + " --model cmu41");
  ASSERT_EQ(whole.status, 0) << whole.err;
  const auto a = gmr("positions " + path("live.gmr") + " --frames 300:301");
  const auto b = gmr("positions " + path("whole.gmr") + " --frames 300:301");
  ASSERT_EQ(a.status, 0);
  ASSERT_EQ(b.status, 0);
  EXPECT_EQ(lines(a.out), 1 + 21u);
  EXPECT_NE(a.out, b.out);
  expect_one_line_error("convert " + c3d + " " + path("w.gmr") + " --model cmu41 --calibrate-seconds -1",
                        "give a number of seconds > 0");
  expect_one_line_error("convert " + c3d + " " + path("w.trc") + " --calibrate-seconds 2",
                        "--calibrate-seconds make a motion");
}

}  // namespace
}  // namespace gmr
