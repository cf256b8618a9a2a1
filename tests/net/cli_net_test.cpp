// The `gmr` server commands against an in-process server: `gmr query` prints
// byte for byte what `gmr positions` prints for the same file and options,
// `gmr stream` prints the same rows, errors are one line with exit status 1.
#include <gtest/gtest.h>

#include <algorithm>

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

// Runs the gmr command with `args` (shell-quoted by the caller), stdout
// captured, stderr merged. Without `prefix_binary`, `args` is the whole
// command line.
CommandRun gmr(const std::string& args, bool prefix_binary = true) {
  CommandRun r;
  const std::string cmd = (prefix_binary ? std::string(GMR_CLI_PATH) + " " : std::string()) + args + " 2>&1";
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
                                 " --strip-dummies --relative-to LeftFoot",
                                 " --conventions unreal --metres-per-unit 0.0254", " --relative-to Head --conventions unity"}) {
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

// Over TLS, with a token: the same rows as a plain server's; without the
// token a structural edit is one line naming the role, and a wrong token
// one line naming the refusal.
TEST(CliNet, TlsAndTokensGiveTheSameRows) {
  const auto cert = self_signed("IP:127.0.0.1");
  server::ServerConfig cfg;
  cfg.tls_certificate_file = cert->cert.string();
  cfg.tls_key_file = cert->key.string();
  auto auth = server::Credentials::parse("control 0123456789abcdef0123\n", "auth");
  ASSERT_TRUE(auth.ok());
  cfg.credentials = std::make_shared<const server::Credentials>(std::move(auth).value());
  cfg.anonymous = server::Role::kRead;
  TestServer tls(cfg);
  TestServer plain;
  const std::string query = "query walk --frames 0:20 --roots l_hand --relative-to head";
  const CommandRun expected = gmr(query + " --port " + std::to_string(plain.port()));
  ASSERT_EQ(expected.status, 0) << expected.out;
  const std::string secure = " --port " + std::to_string(tls.port()) + " --tls-ca '" + cert->cert.string() + "'";
  const CommandRun with_token = gmr(query + secure + " --token 0123456789abcdef0123");
  ASSERT_EQ(with_token.status, 0) << with_token.out;
  EXPECT_EQ(with_token.out, expected.out);
  const CommandRun from_env = gmr("GMR_TOKEN=0123456789abcdef0123 " + std::string(GMR_CLI_PATH) + " " + query + secure,
                                  /*prefix_binary=*/false);
  ASSERT_EQ(from_env.status, 0) << from_env.out;
  EXPECT_EQ(from_env.out, expected.out);
  const CommandRun anonymous = gmr(query + secure);
  EXPECT_EQ(anonymous.status, 1);
  EXPECT_EQ(anonymous.out.rfind("gmr: PERMISSION_DENIED: this connection's role is 'read'", 0), 0u) << anonymous.out;
  EXPECT_EQ(std::count(anonymous.out.begin(), anonymous.out.end(), '\n'), 1);
  const CommandRun wrong = gmr(query + secure + " --token 0123456789abcdef0124");
  EXPECT_EQ(wrong.status, 1);
  EXPECT_NE(wrong.out.find("UNAUTHENTICATED: the server does not know this token"), std::string::npos) << wrong.out;
  const CommandRun untrusted = gmr("ls --tls --port " + std::to_string(tls.port()));
  EXPECT_EQ(untrusted.status, 1);
  EXPECT_NE(untrusted.out.find("certificate verify failed"), std::string::npos) << untrusted.out;
}

}  // namespace
}  // namespace gmr::test
