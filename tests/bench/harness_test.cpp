// gmr-bench, the research harness: the JSON of `fk` and the CSV and plot of `figure4`.
// Only the shape and the consistency of the results are asserted here, never
// a time (speed is measured by the benchmarks, docs/performance.md).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "cli_test_util.h"
#include "gmr/core/file_util.h"
#include "gmr/io/motion_file.h"
#include "test_data.h"

namespace gmr {
namespace {
namespace fs = std::filesystem;
using test::shell_quote;
using ::testing::HasSubstr;

class BenchHarness : public test::CliTest {};

TEST_F(BenchHarness, FkJsonHasEveryPathAndTheFilesSizes) {
  GMR_REQUIRE_DATA();
  const fs::path file = test::data_file("bvh/cmu/cmu_unidentified_75f.bvh");
  const Motion m = load_motion(file).value();
  const auto r = gmr("fk " + shell_quote(file.string()) + " --json --repeat 3");
  ASSERT_EQ(r.status, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);  // exactly one JSON object on stdout
  EXPECT_EQ(j.at("frames").get<std::size_t>(), m.frame_count);
  EXPECT_EQ(j.at("joints").get<std::size_t>(), m.skeleton.size());
  EXPECT_EQ(j.at("repeats").get<int>(), 3);
  const std::vector<std::string> paths = {"bvh_reference_double", "bvh_scalar",   "bvh_fast",
                                          "bvh_fast_frame_major", "gmr_one_root", "gmr_one_root_frame_major",
                                          "gmr_all_roots",        "single_frame", "single_frame_bvh"};
  for (const char* key : {"ns_per_frame", "ns_per_frame_min"}) {
    SCOPED_TRACE(key);
    const auto& ns = j.at(key);
    for (const auto& p : paths) {
      ASSERT_TRUE(ns.contains(p)) << p;
      EXPECT_GT(ns.at(p).get<double>(), 0.0) << p;
    }
    EXPECT_EQ(ns.at("gmr_all_roots_view").get<double>(), 0.0);  // a view, no work
  }
  for (const auto& p : paths) {
    EXPECT_LE(j["ns_per_frame_min"][p].get<double>(), j["ns_per_frame"][p].get<double>()) << p;
  }
  // Bytes per frame follow from the file: doubles per channel, floats per position.
  const auto& bytes = j.at("bytes_per_frame");
  EXPECT_EQ(bytes.at("bvh_values_double").get<std::size_t>(), m.stride() * sizeof(double));
  EXPECT_EQ(bytes.at("positions_float").get<std::size_t>(), m.skeleton.size() * 3 * sizeof(float));
  EXPECT_GT(bytes.at("frame_program_angles").get<std::size_t>(), 0u);

  // The text form names every path too.
  const auto text = gmr("fk " + shell_quote(file.string()) + " --repeat 1");
  ASSERT_EQ(text.status, 0) << text.err;
  for (const auto& p : paths) EXPECT_THAT(text.out, HasSubstr(p));
}

TEST_F(BenchHarness, Figure4WritesOneRowPerConfigurationAndAPlot) {
  GMR_REQUIRE_DATA();
  // Two real files and a malformed one, which is skipped with a message.
  const fs::path in = dir_ / "in";
  fs::create_directories(in / "sub");
  fs::create_symlink(test::data_file("bvh/cmu/cmu_unidentified_75f.bvh"), in / "a.bvh");
  fs::create_symlink(test::data_file("bvh/cmu/02_01.bvh"), in / "sub" / "b.BVH");
  fs::create_symlink(test::data_file("malformed/TRUNC_02_01_mid_frame.bvh"), in / "broken.bvh");
  const auto r = gmr("figure4 " + shell_quote(in.string()) + " --out " + path("fig.csv") + " --plot " +
                     path("fig.png") + " --sets 2 --step 10 --repeat 1");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_THAT(r.err, HasSubstr("skipping"));
  EXPECT_THAT(r.err, HasSubstr("broken.bvh"));

  const std::string csv = read_file(dir_ / "fig.csv").value();
  std::istringstream lines(csv);
  std::string line;
  std::getline(lines, line);
  EXPECT_EQ(line, "file,frames,joints,method,roots,set,ns_per_frame");
  // file -> method -> roots -> sets seen
  std::map<std::string, std::map<std::string, std::map<std::size_t, std::set<int>>>> seen;
  std::map<std::string, std::size_t> joints_of;
  while (std::getline(lines, line)) {
    std::vector<std::string> f;
    std::istringstream ls(line);
    for (std::string item; std::getline(ls, item, ',');) f.push_back(item);
    ASSERT_EQ(f.size(), 7u) << line;
    joints_of[f[0]] = std::stoul(f[2]);
    EXPECT_GT(std::stod(f[6]), 0.0) << line;
    EXPECT_TRUE(seen[f[0]][f[3]][std::stoul(f[4])].insert(std::stoi(f[5])).second) << "repeated row: " << line;
  }
  ASSERT_EQ(seen.size(), 2u);
  for (const auto& [name, file] : std::map<std::string, std::string>{{"a.bvh", "bvh/cmu/cmu_unidentified_75f.bvh"},
                                                                     {"sub/b.BVH", "bvh/cmu/02_01.bvh"}}) {
    SCOPED_TRACE(name);
    const std::size_t n = load_motion(test::data_file(file)).value().skeleton.size();
    EXPECT_EQ(joints_of[name], n);
    const auto& methods = seen[name];
    for (const char* bvh : {"bvh_reference_double", "bvh_scalar_float", "bvh_fast"}) {
      ASSERT_TRUE(methods.count(bvh)) << bvh;
      EXPECT_EQ(methods.at(bvh).size(), 1u) << bvh;
    }
    // GMR: k = 1, 11, 21, ... < n and n (all roots); one set for the
    // conversion's own root and for all roots, two otherwise.
    ASSERT_TRUE(methods.count("gmr_fast"));
    std::map<std::size_t, std::set<int>> want;
    for (std::size_t k = 1; k < n; k += 10) want[k] = k == 1 ? std::set<int>{0} : std::set<int>{0, 1};
    want[n] = {0};
    EXPECT_EQ(methods.at("gmr_fast"), want);
  }

  if (r.err.find("gnuplot not found") == std::string::npos) {
    const std::string png = read_file(dir_ / "fig.png").value();
    ASSERT_GE(png.size(), 8u);
    EXPECT_EQ(png.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
    // Replotting the CSV gives the same kind of file without measuring again.
    const auto again = gmr("figure4 --replot " + path("fig.csv") + " --plot " + path("again.png"));
    ASSERT_EQ(again.status, 0) << again.err;
    EXPECT_EQ(read_file(dir_ / "again.png").value().substr(0, 8), png.substr(0, 8));
  } else if (test::in_ci()) {
    ADD_FAILURE() << "CI installs gnuplot, but gmr bench did not find it";
  }
}

TEST_F(BenchHarness, MisuseFailsWithOneLine) {
  expect_one_line_error("fk " + path("missing.bvh") + " --json", "missing.bvh");
  expect_one_line_error("fk " + path("missing.bvh") + " --repeat 0", "--repeat");
  expect_one_line_error("figure4 " + path("nowhere"), "--out");
  expect_one_line_error("figure4 " + path("nowhere") + " --out " + path("x.csv"), "not a directory");
  fs::create_directories(dir_ / "empty");
  expect_one_line_error("figure4 " + path("empty") + " --out " + path("x.csv"), "no .bvh files");
  expect_one_line_error("figure4 " + path("empty") + " --out " + path("x.csv") + " --sets 0", "--sets");
  ASSERT_TRUE(
      write_file_atomic(dir_ / "bad.csv", "file,frames,joints,method,roots,set,ns_per_frame\na.bvh,1,2\n").ok());
  expect_one_line_error("figure4 --replot " + path("bad.csv") + " --plot " + path("p.png"), "bad.csv:2");
  expect_one_line_error("figure4 --replot " + path("bad.csv"), "--plot");
  EXPECT_FALSE(fs::exists(dir_ / "x.csv"));
}

}  // namespace
}  // namespace gmr
