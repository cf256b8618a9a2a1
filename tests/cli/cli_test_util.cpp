#include "cli_test_util.h"

#include <gmock/gmock.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdlib>

#include "gmr/core/file_util.h"

namespace gmr::test {
namespace fs = std::filesystem;

std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

CliOutcome CliTest::gmr(const std::string& args) {
  const fs::path out = dir_ / "stdout", err = dir_ / "stderr";
  const std::string cmd =
      shell_quote(GMR_CLI_PATH) + " " + args + " >" + shell_quote(out.string()) + " 2>" + shell_quote(err.string());
  const int raw = std::system(cmd.c_str());
  CliOutcome r;
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  r.out = read_file(out).value();
  r.err = read_file(err).value();
  return r;
}

std::string CliTest::path(const std::string& name) const { return shell_quote((dir_ / name).string()); }

void CliTest::expect_one_line_error(const std::string& args, const std::string& needle) {
  const CliOutcome r = gmr(args);
  EXPECT_EQ(r.status, 1) << args;
  // Each program names itself: "gmr: ...", "gmr-bench: ...".
  const std::string prefix = fs::path(GMR_CLI_PATH).filename().string() + ": ";
  EXPECT_THAT(r.err, ::testing::StartsWith(prefix)) << args;
  EXPECT_THAT(r.err, ::testing::HasSubstr(needle)) << args;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

}  // namespace gmr::test
