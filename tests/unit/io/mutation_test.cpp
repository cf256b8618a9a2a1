// Deterministic mutation test of the BVH and GMR readers: real files cut at
// every byte and corrupted at seeded random places must give either a valid
// motion or an error with a line and column, never a crash, a hang or a
// sanitizer report (this program runs under ASan/UBSan in `make test-sanitize`).
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "gmr/io/bvh.h"
#include "gmr/core/file_util.h"
#include "gmr/io/gmr_file.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "io_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {

using Parse = Result<Motion> (*)(std::string_view, std::string_view, Warnings*);

// Parses `text`; on success the motion must be valid and usable.
void check_one(Parse parse, std::string_view text, const std::string& what) {
  Warnings w;
  auto r = parse(text, "m", &w);
  if (!r.ok()) {
    ASSERT_GT(r.error().line, 0) << what << ": " << r.error().to_string();
    ASSERT_GT(r.error().column, 0) << what << ": " << r.error().to_string();
    ASSERT_FALSE(r.error().message.empty()) << what;
    return;
  }
  ASSERT_TRUE(r->validate().ok()) << what;
  if (r->frame_count > 0 && !r->skeleton.empty()) {
    std::vector<Eigen::Vector3d> p(r->skeleton.size());
    compute_frame(*r, r->frame_count - 1, p);
  }
}

struct Case {
  std::string name;
  std::string text;
  Parse parse;
};

std::vector<Case> corpus() {
  std::vector<Case> out;
  for (const auto& path : test::data_files("bvh/parser_fixtures", ".bvh")) {
    out.push_back({path.filename().string(), read_file(path).value(), &parse_bvh});
  }
  // A CRLF CMU file: its hierarchy and first rows.
  std::string cmu = read_file(test::data_file("bvh/cmu/02_01.bvh")).value();
  out.push_back({"02_01.bvh (head)", cmu.substr(0, 6000), &parse_bvh});
  // The same skeleton as GMR text.
  Motion m = parse_bvh(cmu, "02_01").value();
  m.convention = Convention::kPreRotation;
  m.values.resize(3 * m.stride());
  m.frame_count = 3;
  out.push_back({"02_01.gmr", format_gmr(m).value(), &parse_gmr});
  return out;
}

TEST(ReaderMutation, TruncatedAtEveryByte) {
  GMR_REQUIRE_DATA();
  for (const Case& c : corpus()) {
    // Every byte in Release; every 5th in Debug/sanitizer builds (the cut
    // points still land in every kind of token).
    const std::size_t step = test::kSlowBuild ? 5 : 1;
    for (std::size_t n = 0; n <= c.text.size(); n += step) {
      check_one(c.parse, std::string_view(c.text).substr(0, n), c.name + " cut at " + std::to_string(n));
      if (HasFatalFailure()) return;
    }
  }
}

TEST(ReaderMutation, CorruptedBytesAndSpans) {
  GMR_REQUIRE_DATA();
  static constexpr char kBytes[] = {'{', '}',  '-', '.', 'e', 'E',    '+',    '\0', '\r', '\n',
                                    ' ', '\t', '9', 'J', ':', '\x7f', '\xff', 'n',  'i'};
  std::mt19937 rng(20120224);
  for (const Case& c : corpus()) {
    for (int i = 0; i < (test::kSlowBuild ? 400 : 1500); ++i) {
      std::string t = c.text;
      const std::size_t at = rng() % t.size();
      switch (i % 4) {
        case 0:
          t[at] = kBytes[rng() % sizeof kBytes];
          break;  // replace a byte
        case 1:
          t.erase(at, 1 + rng() % 40);
          break;  // delete a span
        case 2:
          t.insert(at, t.substr(rng() % t.size(), 1 + rng() % 60));
          break;  // duplicate a span
        case 3:
          t.insert(at, 1, kBytes[rng() % sizeof kBytes]);
          break;  // insert a byte
      }
      check_one(c.parse, t, c.name + " mutation " + std::to_string(i));
      if (HasFatalFailure()) return;
    }
  }
}

}  // namespace
}  // namespace gmr
