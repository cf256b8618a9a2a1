// Who may do what (docs/security.md): the tokens of the server's auth file,
// each with a role, checked once per connection at Hello.
//
//   # role    token (at least 128 bits; `openssl rand -hex 16` makes one)
//   control   3f6c0d1e9a2b4c5d8e7f6a5b4c3d2e1f
//   read      0a1b2c3d4e5f60718293a4b5c6d7e8f9   # anything after the token is a comment
//   publish   9f8e7d6c5b4a39281706f5e4d3c2b1a0   # a live source (docs/protocol.md, "Live sources")
//
// A token has at most 256 characters and at least 128 bits as estimated
// from its length and character classes (and 8 distinct characters); a
// longer one offered at Hello is refused unhashed.
//
// Tokens are kept as SHA-256 digests and compared in constant time, every
// entry each time: how long a check takes says nothing of which token, or
// how much of one, matched.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"

namespace gmr::server {

// What a connection may do. kRead: list, skeletons, views and their
// viewpoint, queries, subscriptions. kControl: also structural view edits
// and server statistics. kPublish: also publishes live sources. kNone:
// nothing (refused at Hello). Each role may do what the ones before it may.
enum class Role : std::uint8_t { kNone, kRead, kControl, kPublish };

// "none", "read", "control" or "publish".
const char* role_name(Role role);
Result<Role> parse_role(std::string_view name);

class Credentials {
 public:
  // The auth file's text; `source` names it in errors ("auth.txt:3: ...").
  static Result<Credentials> parse(std::string_view text, const std::string& source);
  // Reads and parses `path`. `warning` (may be null) is set when the file
  // can be read by other users than its owner.
  static Result<Credentials> load(const std::string& path, std::string* warning = nullptr);

  static constexpr std::size_t kMaxTokenBytes = 256;

  // The role of `token`; kNone when the file has no such token.
  Role role_of(std::string_view token) const;
  std::size_t size() const { return entries_.size(); }

 private:
  struct Entry {
    std::array<std::uint8_t, 32> digest{};
    Role role = Role::kNone;
  };
  std::vector<Entry> entries_;
};

}  // namespace gmr::server
