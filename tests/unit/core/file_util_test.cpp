#include "gmr/core/file_util.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "gmr/io/bvh.h"
#include "test_data.h"

namespace gmr {
namespace {
namespace fs = std::filesystem;
using ::testing::HasSubstr;

using test::TempDir;

TEST(ReadFile, MissingFileNamesThePath) {
  auto r = read_file("/nonexistent/dir/x.bvh");
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().file, "/nonexistent/dir/x.bvh");
  EXPECT_THAT(r.error().to_string(), HasSubstr("/nonexistent/dir/x.bvh: cannot open file"));
}

TEST(ReadFile, DirectoryIsAnError) {
  TempDir d;
  auto r = read_file(d.path);
  ASSERT_FALSE(r.ok());
  EXPECT_THAT(r.error().message, HasSubstr("directory"));
}

TEST(WriteFileAtomic, WritesAndReplaces) {
  TempDir d;
  const fs::path p = d.path / "out.bvh";
  ASSERT_TRUE(write_file_atomic(p, "first").ok());
  EXPECT_EQ(read_file(p).value(), "first");
  std::string big(3 << 20, 'x');
  big[12345] = '\0';
  ASSERT_TRUE(write_file_atomic(p, big).ok());
  EXPECT_EQ(read_file(p).value(), big);
  ASSERT_TRUE(write_file_atomic(p, "").ok());
  EXPECT_EQ(read_file(p).value(), "");
  EXPECT_EQ(d.entries(), 1u);  // no temporary left behind
}

TEST(WriteFileAtomic, FailureLeavesTheOldFileAndNoTemporary) {
  TempDir d;
  // The target is a directory holding a file: the write must fail, keep both.
  const fs::path target = d.path / "target.gmr";
  fs::create_directories(target);
  ASSERT_TRUE(write_file_atomic(target / "old.gmr", "old contents").ok());
  const Status s = write_file_atomic(target, "new contents");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().file, target.string());
  EXPECT_EQ(read_file(target / "old.gmr").value(), "old contents");
  EXPECT_EQ(d.entries(), 1u);

  // A missing directory: an error naming the path, nothing created.
  const Status m = write_file_atomic(d.path / "missing" / "x.bvh", "data");
  ASSERT_FALSE(m.ok());
  EXPECT_THAT(m.error().to_string(), HasSubstr((d.path / "missing" / "x.bvh").string()));
  EXPECT_FALSE(fs::exists(d.path / "missing"));
}

TEST(WriteFileAtomic, WriterErrorKeepsTheOldFile) {
  TempDir d;
  const fs::path p = d.path / "keep.bvh";
  ASSERT_TRUE(write_file_atomic(p, "old").ok());
  Motion pre;  // empty: nothing to write
  const Status s = write_bvh(pre, p);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().file, p.string());
  EXPECT_EQ(read_file(p).value(), "old");
  EXPECT_EQ(d.entries(), 1u);
}

TEST(WriteFileAtomic, KeepsPermissionsOfTheReplacedFile) {
  TempDir d;
  const fs::path p = d.path / "mode.bvh";
  ASSERT_TRUE(write_file_atomic(p, "a").ok());
  fs::permissions(p, fs::perms::owner_read | fs::perms::owner_write | fs::perms::others_read);
  ASSERT_TRUE(write_file_atomic(p, "b").ok());
  EXPECT_EQ(fs::status(p).permissions(), fs::perms::owner_read | fs::perms::owner_write | fs::perms::others_read);
}

std::string to_chars_text(double v) {
  char buf[64];
  return std::string(buf, std::to_chars(buf, buf + sizeof buf, v).ptr);
}

// format_double has a fast path; it must write what std::to_chars writes.
// A pid that no process has: a child that exited and was reaped.
pid_t dead_pid() {
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  int status = 0;
  ::waitpid(child, &status, 0);
  return child;
}

TEST(WriteFileAtomic, TheNextWriteSweepsTemporariesOfDeadWriters) {
  TempDir d;
  const auto old = fs::file_time_type::clock::now() - std::chrono::minutes(5);
  const auto make = [&](const std::string& name, bool stale) {
    ASSERT_TRUE(write_file_atomic(d.path / name, "partial").ok());
    if (stale) fs::last_write_time(d.path / name, old);
  };
  const std::string dead = std::to_string(dead_pid());
  const std::string alive = std::to_string(::getppid());
  make(".out.gmr.tmp." + dead + ".0", true);    // a SIGKILLed writer of out.gmr: swept
  make(".out.gmr.tmp." + dead + ".1", false);   // too recent (another machine's writer?): kept
  make(".out.gmr.tmp." + alive + ".0", true);   // its writer is alive: kept
  make(".other.gmr.tmp." + dead + ".0", true);  // another file's: kept until that file is written
  make(".out.gmr.tmp." + dead + ".x", true);    // not our pattern: kept
  ASSERT_EQ(d.entries(), 5u);
  ASSERT_TRUE(write_file_atomic(d.path / "out.gmr", "whole").ok());
  EXPECT_FALSE(fs::exists(d.path / (".out.gmr.tmp." + dead + ".0")));
  EXPECT_EQ(d.entries(), 5u);  // out.gmr and the four kept
  ASSERT_TRUE(write_file_atomic(d.path / "other.gmr", "whole").ok());
  EXPECT_FALSE(fs::exists(d.path / (".other.gmr.tmp." + dead + ".0")));
}

TEST(WriteFileAtomic, ASignalDuringAWriteRemovesItsTemporary) {
  // A child writes 4 MiB with a 64 KiB file size limit; the limit's SIGXFSZ
  // is turned into SIGTERM, which must remove the temporary before the child
  // dies of it (as SIGINT does to an interrupted `gmr convert`).
  TempDir d;
  const pid_t child = ::fork();
  if (child == 0) {
    remove_temporaries_on_signals();
    struct sigaction to_term {};
    to_term.sa_handler = [](int) { ::raise(SIGTERM); };
    ::sigaction(SIGXFSZ, &to_term, nullptr);
    struct rlimit limit {
      64 * 1024, 64 * 1024
    };
    ::setrlimit(RLIMIT_FSIZE, &limit);
    (void)write_file_atomic(d.path / "out.gmr", std::string(4 << 20, 'x'));
    ::_exit(0);  // not reached: SIGTERM ends it
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the child should die of the signal";
  EXPECT_EQ(WTERMSIG(status), SIGTERM);
  EXPECT_EQ(d.entries(), 0u) << "the temporary was left behind";
}

TEST(WriteFileAtomic, PastTheFileSizeLimitIsAnErrorWithNothingLeft) {
  // With the signals handled as the tools do, a write past RLIMIT_FSIZE is
  // an error (EFBIG), not the end of the process, and leaves nothing.
  TempDir d;
  const pid_t child = ::fork();
  if (child == 0) {
    remove_temporaries_on_signals();
    struct rlimit limit {
      64 * 1024, 64 * 1024
    };
    ::setrlimit(RLIMIT_FSIZE, &limit);
    const Status s = write_file_atomic(d.path / "out.gmr", std::string(4 << 20, 'x'));
    ::_exit(!s.ok() && s.error().message.find("File too large") != std::string::npos ? 3 : 4);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 3);
  EXPECT_EQ(d.entries(), 0u);
}

TEST(FormatDouble, SameBytesAsToChars) {
  std::vector<double> values = {0.0,
                                -0.0,
                                1.0,
                                -1.0,
                                10,
                                100,
                                1200000,
                                1e15,
                                999999999999999.0,
                                1e16,
                                0.001,
                                0.0001,
                                0.000123,
                                1e-5,
                                1.5e-6,
                                1e-6,
                                0.1,
                                0.3,
                                0.30000000000000004,
                                123456.789,
                                1.0 / 3.0,
                                2.5e-7,
                                12345678901234.5,
                                1234567890123.45,
                                0.5,
                                5e-324,
                                1.7976931348623157e308,
                                std::numeric_limits<double>::infinity(),
                                std::nan("")};
  std::mt19937_64 rng(99);
  for (int i = 0; i < 200000; ++i) {
    // Short decimals of every length and scale, as motion files hold them.
    const int digits = 1 + static_cast<int>(rng() % 16);
    std::uint64_t m = rng() % 10000000000000000ull;
    for (int d = digits; d < 16; ++d) m /= 10;
    const int k = static_cast<int>(rng() % 20);
    double v = static_cast<double>(m);
    for (int j = 0; j < k; ++j) v /= 10;
    values.push_back(rng() % 2 ? v : -v);
    values.push_back(std::ldexp(static_cast<double>(rng() % (1ull << 53)), static_cast<int>(rng() % 120) - 80));
    char text[32];
    std::snprintf(text, sizeof text, "%.*f", static_cast<int>(rng() % 9),
                  std::ldexp(static_cast<double>(rng() % 100000), -10));
    values.push_back(std::strtod(text, nullptr));
  }
  for (double v : values) ASSERT_EQ(format_double(v), to_chars_text(v)) << std::hexfloat << v;
}

TEST(FormatDouble, SameBytesAsToCharsOnTheCorpus) {
  GMR_REQUIRE_DATA();
  for (const auto& path : test::data_files("bvh", ".bvh")) {
    const Motion m = read_bvh(path).value();
    for (double v : m.values) ASSERT_EQ(format_double(v), to_chars_text(v)) << path << ": " << std::hexfloat << v;
    for (const Joint& j : m.skeleton.joints())
      for (int i = 0; i < 3; ++i) ASSERT_EQ(format_double(j.offset[i]), to_chars_text(j.offset[i])) << path;
  }
}

TEST(FormatDouble, ShortestRoundTrip) {
  EXPECT_EQ(format_double(0.1), "0.1");
  EXPECT_EQ(format_double(-6.101614), "-6.101614");
  EXPECT_EQ(format_double(1e-7), "1e-07");
  EXPECT_EQ(format_double(0.1 + 0.2), "0.30000000000000004");
  EXPECT_EQ(format_double(100), "100");
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> u(-1e3, 1e3);
  for (int i = 0; i < 10000; ++i) {
    const double v = i % 2 ? u(rng) : std::ldexp(u(rng), static_cast<int>(rng() % 600) - 300);
    const std::string s = format_double(v);
    double back = 0;
    std::from_chars(s.data(), s.data() + s.size(), back);
    ASSERT_EQ(back, v) << s;
  }
}

// A pair is written whole or not at all: when the second file cannot be
// written, the first keeps its old content and no temporary is left.
TEST(WriteFilesAtomic, APairIsWrittenWholeOrNotAtAll) {
  TempDir tmp;
  const auto a = tmp.path / "a.asf";
  const auto b = tmp.path / "b.amc";
  ASSERT_TRUE(write_file_atomic(a, "old").ok());
  std::filesystem::create_directories(b);  // b cannot be replaced by a file
  const FileContent bad[] = {{a, "new a"}, {b, "new b"}};
  const Status s = write_files_atomic(bad);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().to_string().find("b.amc"), std::string::npos) << s.error().to_string();
  EXPECT_EQ(read_file(a).value(), "old");
  EXPECT_EQ(tmp.entries(), 2u);  // a.asf and the folder b.amc: no temporary left
  std::filesystem::remove(b);
  const FileContent good[] = {{a, "new a"}, {b, "new b"}};
  ASSERT_TRUE(write_files_atomic(good).ok());
  EXPECT_EQ(read_file(a).value(), "new a");
  EXPECT_EQ(read_file(b).value(), "new b");
  EXPECT_EQ(tmp.entries(), 2u);
}

TEST(LowerExtension, LowerCasesTheExtensionWithItsDot) {
  EXPECT_EQ(lower_extension("a/B.BVH"), ".bvh");
  EXPECT_EQ(lower_extension("walk.Gmrb"), ".gmrb");
  EXPECT_EQ(lower_extension("dir.d/noext"), "");
  EXPECT_EQ(lower_extension("x.tar.GZ"), ".gz");
}

}  // namespace
}  // namespace gmr
