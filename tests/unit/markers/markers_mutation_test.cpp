// Seeded mutation test of the C3D and TRC readers: real files cut at many
// points and corrupted at random must give a valid result or a located error,
// never a crash, a hang or a sanitizer report (runs under ASan/UBSan).
#include <gtest/gtest.h>

#include <random>
#include <string>

#include "gmr/core/file_util.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "io_test_util.h"
#include "test_data.h"

namespace gmr {
namespace {

using Parse = Result<MarkerTrajectories> (*)(std::string_view, std::string_view, Warnings*);

void check_one(Parse parse, bool binary, std::string_view bytes, const std::string& what) {
  Warnings w;
  auto r = parse(bytes, "m", &w);
  if (!r.ok()) {
    ASSERT_EQ(r.error().file, "m") << what;
    if (binary) {
      ASSERT_EQ(r.error().message.rfind("at byte ", 0), 0u) << what << ": " << r.error().to_string();
    } else {
      ASSERT_GT(r.error().line, 0) << what << ": " << r.error().to_string();
      ASSERT_GT(r.error().column, 0) << what << ": " << r.error().to_string();
    }
    return;
  }
  const Status valid = r->validate();
  ASSERT_TRUE(valid.ok()) << what << ": " << valid.error().message;
  (void)r->missing_points();
}

struct Case {
  std::string name;
  std::string bytes;
  Parse parse;
  bool binary;
};

std::vector<Case> corpus() {
  // cmu_02_01 (Intel, float) cut after 20 frames; a short TRC with blank cells.
  std::string c3d = read_file(test::data_file("c3d/cmu_02_01.c3d")).value();
  c3d.resize(6144 + 20 * 656);
  std::string dec = read_file(test::data_file("malformed/ezc3d_read_NOTworking2.c3d")).value();
  dec.resize(2048 + 10 * 23 * 8);
  std::string trc = read_file(test::data_file("trc/edge/exampleFormat_missing_and_nan.trc")).value();
  std::string trc2 = read_file(test::data_file("trc/opensim_walk_free_01.trc")).value().substr(0, 8000);
  return {{"cmu_02_01.c3d", c3d, &parse_c3d, true},
          {"NOTworking2.c3d", dec, &parse_c3d, true},
          {"exampleFormat.trc", trc, &parse_trc, false},
          {"walk_free_01.trc (head)", trc2, &parse_trc, false}};
}

TEST(MarkerMutation, TruncatedAtManyPoints) {
  GMR_REQUIRE_DATA();
  for (const Case& c : corpus()) {
    const std::size_t step = test::kSlowBuild ? 7 : 1;
    for (std::size_t n = 0; n <= c.bytes.size(); n += step) {
      check_one(c.parse, c.binary, std::string_view(c.bytes).substr(0, n), c.name + " cut at " + std::to_string(n));
      if (HasFatalFailure()) return;
    }
  }
}

TEST(MarkerMutation, CorruptedBytesAndSpans) {
  GMR_REQUIRE_DATA();
  static constexpr char kBytes[] = {'\t', ',',  ' ',    '\r',   '\n',   '-',    '.',    'e',    'N',    'a',
                                    '9',  '\0', '\x7f', '\xff', '\x80', '\x01', '\x50', '\x54', '\x55', '\x56'};
  std::mt19937 rng(20261122);
  for (const Case& c : corpus()) {
    for (int i = 0; i < (test::kSlowBuild ? 600 : 3000); ++i) {
      std::string t = c.bytes;
      // C3D: aim most hits at the header and parameters, where the sizes are.
      const std::size_t range = c.binary && i % 3 != 0 ? std::min<std::size_t>(t.size(), 2048) : t.size();
      const std::size_t at = rng() % range;
      switch (i % 4) {
        case 0:
          t[at] = kBytes[rng() % sizeof kBytes];
          break;
        case 1:
          t[at] = static_cast<char>(rng());
          break;
        case 2:
          t.erase(at, 1 + rng() % 40);
          break;
        case 3:
          t.insert(at, t.substr(rng() % t.size(), 1 + rng() % 60));
          break;
      }
      check_one(c.parse, c.binary, t, c.name + " mutation " + std::to_string(i));
      if (HasFatalFailure()) return;
    }
  }
}

}  // namespace
}  // namespace gmr
