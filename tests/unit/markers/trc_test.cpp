// TRC reader and writer: every real file with facts from PROVENANCE.md, the
// edge files (NaN spellings, blank cells, E-notation, CRLF), small texts for
// the header variants and the errors, and the round trips.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "gmr/core/file_util.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "markers_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {

// Bit-identical positions (NaN equal to NaN).
void expect_same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::isnan(a[i]) || std::isnan(b[i])) {
      ASSERT_TRUE(std::isnan(a[i]) && std::isnan(b[i])) << "value " << i;
    } else {
      ASSERT_EQ(std::memcmp(&a[i], &b[i], sizeof(double)), 0) << "value " << i << ": " << a[i] << " vs " << b[i];
    }
  }
}

TEST(RealFiles, OpensimTrc) {
  GMR_REQUIRE_DATA();
  Warnings w;
  const auto a = test::load_marker_file("trc/opensim_std_walking2_markers.trc", &w);
  EXPECT_EQ(a.marker_count(), 44u);
  EXPECT_EQ(a.frame_count, 126u);
  EXPECT_EQ(a.frame_rate, 250.0);
  EXPECT_EQ(a.units, "mm");
  EXPECT_EQ(a.names.front(), "RTH1");
  // Its Time column steps by 0.04 s (every 10th frame of the trial), not 1/250.
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].line, 8);
  EXPECT_NE(w[0].message.find("does not match DataRate"), std::string::npos);

  w.clear();
  const auto s = test::load_marker_file("trc/opensim_subject01_static.trc", &w);
  EXPECT_TRUE(w.empty());
  EXPECT_EQ(s.marker_count(), 49u);
  EXPECT_EQ(s.frame_count, 300u);
  EXPECT_EQ(s.frame_rate, 60.0);
  EXPECT_EQ(s.names[0], "R.ASIS");
  EXPECT_EQ(s.names[2], "V.Sacral");
  EXPECT_EQ(s.missing_points(), 0u);

  w.clear();
  const auto f = test::load_marker_file("trc/opensim_walk_free_01.trc", &w);
  EXPECT_EQ(f.marker_count(), 41u);
  EXPECT_EQ(f.frame_count, 73u);
  EXPECT_EQ(f.first_frame, 185);
  EXPECT_EQ(f.start_time, 3.067);
  EXPECT_EQ(f.positions[0], 596.88123);
  ASSERT_EQ(w.size(), 1u);  // NumFrames 900
  EXPECT_EQ(w[0].line, 3);
  EXPECT_NE(w[0].message.find("NumFrames is 900 but the file holds 73 rows"), std::string::npos);
}

TEST(RealFiles, Pose2simAndCommaSeparated) {
  GMR_REQUIRE_DATA();
  const auto p = test::load_marker_file("trc/pose2sim_BalancingTrial_0-100.trc");
  EXPECT_EQ(p.marker_count(), 21u);
  EXPECT_EQ(p.frame_count, 100u);
  EXPECT_EQ(p.units, "m");
  EXPECT_EQ(p.names[0], "RHip");
  EXPECT_EQ(p.positions[0], -0.06497214796810755);

  Warnings w;
  const auto c = test::load_marker_file("trc/pyomeca_markers.trc", &w);
  EXPECT_EQ(c.marker_count(), 51u);
  EXPECT_EQ(c.frame_count, 93u);
  EXPECT_EQ(c.frame_rate, 100.0);
  EXPECT_EQ(c.names[0], "ASISl");
  EXPECT_EQ(c.positions[0], 733.7041);
  EXPECT_EQ(c.positions[2], 191.8668);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].message.find("NumFrames is 652"), std::string::npos);
}

TEST(RealFiles, EdgeTrc) {
  GMR_REQUIRE_DATA();
  const auto e = test::load_marker_file("trc/edge/dataWithEformat.trc");
  EXPECT_EQ(e.marker_count(), 14u);
  EXPECT_EQ(e.frame_count, 5u);
  EXPECT_EQ(e.frame_rate, 119.88012);
  EXPECT_EQ(e.positions[0], -0.273);  // -2.73E-01

  const auto n = test::load_marker_file("trc/edge/dataWithNaNsOfDifferentCases.trc");
  EXPECT_EQ(n.marker_count(), 14u);
  EXPECT_EQ(n.frame_count, 5u);
  EXPECT_EQ(n.missing_points(), 5u);  // marker 9 ("thigh") in every frame: NaN, NAN, Nan, naN ...
  for (std::size_t f = 0; f < 5; ++f) EXPECT_TRUE(std::isnan(n.positions[n.index(f, 8, 0)]));

  const auto m = test::load_marker_file("trc/edge/exampleFormat_missing_and_nan.trc");
  EXPECT_EQ(m.names, (std::vector<std::string>{"marker1", "marker2", "marker3"}));
  EXPECT_EQ(m.frame_count, 5u);
  EXPECT_EQ(m.missing_points(), 2u);
  EXPECT_TRUE(std::isnan(m.positions[m.index(0, 0, 0)]));  // blank cells
  EXPECT_TRUE(std::isnan(m.positions[m.index(2, 1, 2)]));  // Nan nan NAN
  EXPECT_EQ(m.positions[m.index(1, 0, 1)], 0.0745);
  EXPECT_EQ(m.positions[m.index(4, 2, 2)], -1.7);  // last row, no final newline

  const auto c = test::load_marker_file("trc/edge/gait10dof18musc_walk_CRLF_line_ending.trc");
  EXPECT_EQ(c.marker_count(), 41u);
  EXPECT_EQ(c.frame_count, 10u);
}

TEST(RealFiles, EveryMarkerFileLoads) {
  GMR_REQUIRE_DATA();
  std::size_t files = 0;
  for (const char* sub : {"c3d", "trc"}) {
    for (const auto& p : test::data_files(sub, std::string(".") + sub)) {
      auto r = load_markers(p);
      ASSERT_TRUE(r.ok()) << r.error().to_string();
      EXPECT_TRUE(r->validate().ok()) << p;
      EXPECT_GT(r->frame_count, 0u) << p;
      ++files;
    }
  }
  EXPECT_EQ(files, 6u + 9u);  // data_files recurses: trc/ and trc/edge/
}

TEST(Malformed, TruncatedTrcRow) {
  GMR_REQUIRE_DATA();
  const std::string path = test::data_file("malformed/TRUNC_opensim_walk_free_01_mid_row.trc").string();
  auto r = read_trc(path);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().to_string(),
            path + ":35:689: file ends after 64 of 125 values (Frame#, Time and 3 per marker): truncated");
}

constexpr char kHeader7Spaces[] =
    "PathFileType 4 (X/Y/Z) s.trc\r\n"
    "DataRate CameraRate NumFrames NumMarkers Units OrigDataRate OrigDataStartFrame\r\n"
    "10 10 2 3 m 10 1\r\n"
    "Frame# Time A B\r\n"
    "X0 Y0 Z0 X1 Y1 Z1\r\n"
    "\r\n"
    "5 0.5 1 2 3 nan NaN NAN\r\n"
    "6 0.6 +1e2 -2.5E-1 3 4 5 6\r\n";

TEST(SmallTrc, SpacesCrlfSevenKeysX0) {
  Warnings w;
  auto r = parse_trc(kHeader7Spaces, "s.trc", &w);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  EXPECT_EQ(r->names, (std::vector<std::string>{"A", "B"}));
  EXPECT_EQ(r->frame_count, 2u);
  EXPECT_EQ(r->first_frame, 5);
  EXPECT_EQ(r->start_time, 0.5);
  EXPECT_EQ(r->positions[6], 100.0);
  EXPECT_EQ(r->positions[7], -0.25);
  EXPECT_EQ(r->missing_points(), 1u);
  ASSERT_EQ(w.size(), 1u);  // NumMarkers 3 for 2 names
  EXPECT_EQ(w[0].to_string(), "s.trc:3:9: NumMarkers is 3 but 2 marker names follow: using the names");
}

TEST(SmallTrc, RepeatedNamesAreRenamed) {
  Warnings w;
  auto r = parse_trc("PathFileType\t4\nDataRate\n1\nFrame#\tTime\tA\t\t\tA\t\t\n1\t0\t1\t2\t3\t4\t5\t6\n", "d.trc", &w);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  EXPECT_EQ(r->names, (std::vector<std::string>{"A", "A_2"}));
  EXPECT_EQ(r->positions[3], 4.0);  // no coordinate-label line: the row right after the names
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].line, 4);
  EXPECT_TRUE(r->validate().ok());
}

TEST(SmallTrc, ErrorsHaveLineAndColumn) {
  const auto error_of = [](std::string text) {
    auto r = parse_trc(text, "t.trc");
    return r.ok() ? std::string("ok") : r.error().to_string();
  };
  const std::string head =
      "PathFileType\t4\n"
      "DataRate\tNumFrames\n"
      "10\t1\n"
      "Frame#\tTime\tA\t\t\n"
      "\t\tX1\tY1\tZ1\n";
  EXPECT_EQ(error_of(head + "1\t0\t1\t2\t3\n"), "ok");
  EXPECT_EQ(error_of(head + "1\t0\t1\tx2\t3\n"),
            "t.trc:6:7: expected a number, NaN or an empty cell for A, found 'x2'");
  EXPECT_EQ(error_of(head + "1\t0\t1\tinf\t3\n"),
            "t.trc:6:7: expected a number, NaN or an empty cell for A, found 'inf'");
  EXPECT_EQ(error_of(head + "1\t0\t1\t2\t3\t4\n"),
            "t.trc:6:11: row has 6 values, expected 5 (Frame#, Time and 3 per marker for 1 markers)");
  EXPECT_EQ(error_of(head + "1\t0\t1\t2\n"), "t.trc:6:8: row ends after 4 of 5 values (Frame#, Time and 3 per marker)");
  EXPECT_EQ(error_of(head + "a\t0\t1\t2\t3\n"), "t.trc:6:1: expected a frame number, found 'a'");
  EXPECT_EQ(error_of(""), "t.trc:1:1: empty file: expected a TRC header (PathFileType ...)");
  EXPECT_EQ(error_of("hello\n"), "t.trc:1:1: expected 'PathFileType' at the start of a TRC file");
  EXPECT_EQ(error_of("PathFileType\t4\nDataRate\n"),
            "t.trc:3:1: expected the header values line, found the end of the file");
  EXPECT_EQ(error_of("PathFileType\t4\nDataRate\nfast\nFrame#\tTime\n"),
            "t.trc:3:1: DataRate must be a number >= 0, found 'fast'");
  EXPECT_EQ(error_of("PathFileType\t4\nDataRate\n1\nFrame\tTime\n"),
            "t.trc:4:1: expected 'Frame#' and 'Time' to start the marker names line");
}

TEST(RoundTrip, TrcWriteReadIsExact) {
  GMR_REQUIRE_DATA();
  test::TempDir dir;
  for (const char* rel : {"trc/pose2sim_BalancingTrial_0-100.trc", "trc/edge/exampleFormat_missing_and_nan.trc",
                          "trc/opensim_walk_free_01.trc", "trc/pyomeca_markers.trc"}) {
    SCOPED_TRACE(rel);
    const auto a = test::load_marker_file(rel);
    const auto out = dir.path / "out.trc";
    ASSERT_TRUE(write_trc(a, out).ok());
    Warnings w;
    auto b = read_trc(out, &w);
    ASSERT_TRUE(b.ok()) << b.error().to_string();
    EXPECT_TRUE(w.empty()) << w.front().to_string();
    EXPECT_EQ(b->names, a.names);
    EXPECT_EQ(b->frame_count, a.frame_count);
    EXPECT_EQ(b->first_frame, a.first_frame);
    EXPECT_EQ(b->frame_rate, a.frame_rate);
    EXPECT_EQ(b->start_time, a.start_time);
    EXPECT_EQ(b->units, a.units);
    expect_same_bits(a.positions, b->positions);
  }
}

TEST(RoundTrip, C3dToTrcKeepsEveryPosition) {
  GMR_REQUIRE_DATA();
  test::TempDir dir;
  for (const char* rel : {"c3d/opensim_walking2.c3d", "c3d/cmu_02_01.c3d", "malformed/ezc3d_read_NOTworking2.c3d"}) {
    SCOPED_TRACE(rel);
    auto a = read_c3d(test::data_file(rel));
    ASSERT_TRUE(a.ok());
    const auto out = dir.path / "out.trc";
    ASSERT_TRUE(write_trc(*a, out).ok());
    auto b = read_trc(out);
    ASSERT_TRUE(b.ok()) << b.error().to_string();
    EXPECT_EQ(b->names, a->names);
    EXPECT_EQ(b->first_frame, a->first_frame);
    EXPECT_EQ(b->frame_rate, a->frame_rate);
    EXPECT_EQ(b->units, a->units);
    expect_same_bits(a->positions, b->positions);
  }
}

TEST(Writer, RejectsWhatCannotBeReadBack) {
  MarkerTrajectories d;
  d.names = {"a\tb"};
  d.frame_count = 1;
  d.positions = {1, 2, 3};
  EXPECT_FALSE(format_trc(d).ok());
  d.names = {"a"};
  d.positions = {1, INFINITY, 3};
  EXPECT_FALSE(format_trc(d).ok());
  d.positions = {1, 2};
  EXPECT_FALSE(format_trc(d).ok());
  d.positions = {1, 2, 3};
  EXPECT_TRUE(format_trc(d).ok());
}

TEST(LoadMarkers, ByExtension) {
  auto r = load_markers("x.bvh");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().to_string(), "x.bvh: cannot load '.bvh' files as markers: expected .c3d or .trc");
  EXPECT_TRUE(is_marker_file("A.C3D"));
  EXPECT_TRUE(is_marker_file("a.Trc"));
  EXPECT_FALSE(is_marker_file("a.bvh"));
}

}  // namespace
}  // namespace gmr
