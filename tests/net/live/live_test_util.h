// What the live-source tests share: a server configuration with a
// 'publish' and a 'control' token (anonymous clients read), and clients
// connected with either.
#pragma once

#include <memory>
#include <string>

#include "gmr/client/client.h"
#include "gmr/server/auth.h"
#include "net_test_util.h"

namespace gmr::test {

inline const std::string kPublishToken = "publish-token-0123456789abcdef";
inline const std::string kControlToken = "control-token-0123456789abcdef";

inline server::ServerConfig live_config() {
  server::ServerConfig cfg;
  auto c = server::Credentials::parse("publish " + kPublishToken + "\ncontrol " + kControlToken + "\n", "auth");
  EXPECT_TRUE(c.ok());
  cfg.credentials = std::make_shared<const server::Credentials>(std::move(c).value());
  cfg.anonymous = server::Role::kRead;
  return cfg;
}

inline std::unique_ptr<client::Client> connect_as(TestServer& s, const std::string& token) {
  client::ClientOptions o;
  o.auth_token = token;
  return s.connect(o);
}

}  // namespace gmr::test
