// The corpus helpers themselves: a loop over the corpus cannot pass by
// finding nothing.
#include "test_data.h"

#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

namespace gmr::test {
namespace {

TEST(CorpusFiles, FindsExactlyWhatTheCorpusHolds) {
  GMR_REQUIRE_DATA();
  EXPECT_EQ(data_files("bvh", ".bvh").size(), expected_data_files("bvh", ".bvh"));
  EXPECT_EQ(data_files("asfamc", ".amc").size(), 9u);
}

// A corpus where a folder was renamed and another lost files: every loop
// over them fails instead of covering less.
TEST(CorpusFiles, AMissingFolderOrMissingFilesFailTheTest) {
  TempDir shrunk;
  std::filesystem::create_directories(shrunk.path / "bvh");
  { std::ofstream(shrunk.path / "bvh" / "only.bvh") << "HIERARCHY\n"; }
  const std::string old = std::getenv("GMR_DATA_DIR") ? std::getenv("GMR_DATA_DIR") : "";
  ::setenv("GMR_DATA_DIR", shrunk.path.c_str(), 1);
  ASSERT_TRUE(have_data());
  EXPECT_NONFATAL_FAILURE((void)data_files("bvh", ".bvh"), "1 .bvh files found, the corpus holds 44");
  EXPECT_NONFATAL_FAILURE((void)data_files("asfamc", ".amc"), "0 .amc files found, the corpus holds 9");
  EXPECT_NONFATAL_FAILURE((void)data_files("bvh", ".xyz"), "no expected count");
  if (old.empty()) {
    ::unsetenv("GMR_DATA_DIR");
  } else {
    ::setenv("GMR_DATA_DIR", old.c_str(), 1);
  }
}

}  // namespace
}  // namespace gmr::test
