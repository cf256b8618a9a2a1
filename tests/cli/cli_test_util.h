// Running a built command (`gmr`, or the program GMR_CLI_PATH names) from a test: a fresh temporary folder per
// test (test::TempDir), and the command's exit status, stdout and stderr.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "test_data.h"

namespace gmr::test {

struct CliOutcome {
  int status = -1;  // exit status; -1 when the command did not exit normally
  std::string out;
  std::string err;
};

// `s` in single quotes for /bin/sh.
std::string shell_quote(const std::string& s);

class CliTest : public ::testing::Test {
 protected:
  // Runs `gmr ARGS` (ARGS is shell text: quote paths with shell_quote).
  CliOutcome gmr(const std::string& args);
  // The quoted path of `name` inside dir_.
  std::string path(const std::string& name) const;
  // A command that must fail: exit 1 and exactly one line on stderr,
  // starting with the program's name ("gmr: ") and containing `needle`.
  void expect_one_line_error(const std::string& args, const std::string& needle);

  TempDir tmp_;  // a fresh, empty folder per test, removed after it
  const std::filesystem::path& dir_ = tmp_.path;
};

}  // namespace gmr::test
