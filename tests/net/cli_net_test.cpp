// The `gmr` server commands against an in-process server: `gmr query` prints
// byte for byte what `gmr positions` prints for the same file and options,
// `gmr stream` prints the same rows, errors are one line with exit status 1.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <sys/wait.h>

#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

struct CommandRun {
  int status = -1;
  std::string out;
};

// Runs the gmr command with `args` (shell-quoted by the caller), stdout captured, stderr merged.
CommandRun gmr(const std::string& args) {
  CommandRun r;
  const std::string cmd = std::string(GMR_CLI_PATH) + " " + args + " 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  std::array<char, 65536> buf;
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), p)) > 0;) r.out.append(buf.data(), n);
  const int st = ::pclose(p);
  r.status = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

TEST(CliNet, QueryPrintsExactlyWhatPositionsPrints) {
  GMR_REQUIRE_DATA();
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const std::string file = cmu_file().string();
  for (const std::string opts : {"", " --roots LeftHand", " --roots Hips,LeftForeArm --relative-to Head",
                                 " --strip-dummies --relative-to LeftFoot"}) {
    SCOPED_TRACE(opts);
    const CommandRun q = gmr("query cmu/02_01 --frames 10:60" + opts + port);
    const CommandRun p = gmr("positions '" + file + "' --frames 10:60" + opts);
    ASSERT_EQ(q.status, 0) << q.out;
    ASSERT_EQ(p.status, 0) << p.out;
    EXPECT_EQ(q.out, p.out);
    EXPECT_GT(q.out.size(), 1000u);
  }
}

TEST(CliNet, StreamPrintsTheSameRowsAsPositions) {
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const CommandRun st = gmr("stream walk --frames 0:5 --speed 10" + port);
  const CommandRun q = gmr("query walk --frames 0:5" + port);
  ASSERT_EQ(st.status, 0) << st.out;
  ASSERT_EQ(q.status, 0) << q.out;
  EXPECT_EQ(st.out, q.out);
  const CommandRun udp = gmr("stream walk --udp --count 3 --joints head" + port);
  ASSERT_EQ(udp.status, 0) << udp.out;
  EXPECT_EQ(udp.out.rfind("frame,joint,x,y,z\n", 0), 0u) << udp.out;
}

TEST(CliNet, ListAndSkeletonAndOneLineErrors) {
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const CommandRun ls = gmr("ls" + port);
  ASSERT_EQ(ls.status, 0) << ls.out;
  EXPECT_NE(ls.out.find("walk"), std::string::npos);
  const CommandRun sk = gmr("skeleton walk" + port);
  ASSERT_EQ(sk.status, 0) << sk.out;
  EXPECT_NE(sk.out.find("l_hand"), std::string::npos);
  const CommandRun missing = gmr("query nope" + port);
  EXPECT_EQ(missing.status, 1);
  EXPECT_EQ(missing.out, "gmr: NOT_FOUND: unknown motion 'nope'\n");
  const CommandRun joint = gmr("query walk --relative-to tail" + port);
  EXPECT_EQ(joint.status, 1);
  EXPECT_NE(joint.out.find("'tail'"), std::string::npos) << joint.out;
  // Nothing listens on port 1.
  const CommandRun refused = gmr("ls --port 1");
  EXPECT_EQ(refused.status, 1);
  EXPECT_EQ(refused.out.rfind("gmr: cannot connect to 127.0.0.1:1", 0), 0u) << refused.out;
}

}  // namespace
}  // namespace gmr::test
