#include "gmr/server/auth.h"

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <sys/stat.h>

#include "gmr/core/file_util.h"

namespace gmr::server {

namespace {

constexpr std::size_t kMinTokenLength = 16;

std::array<std::uint8_t, 32> sha256(std::string_view text) {
  std::array<std::uint8_t, 32> out{};
  unsigned int n = 0;
  EVP_Digest(text.data(), text.size(), out.data(), &n, EVP_sha256(), nullptr);
  return out;
}

bool is_space(char c) { return c == ' ' || c == '\t' || c == '\r'; }

// The next whitespace-separated word of `line` from `pos`.
std::string_view next_word(std::string_view line, std::size_t& pos) {
  while (pos < line.size() && is_space(line[pos])) ++pos;
  const std::size_t start = pos;
  while (pos < line.size() && !is_space(line[pos])) ++pos;
  return line.substr(start, pos - start);
}

}  // namespace

const char* role_name(Role role) {
  switch (role) {
    case Role::kNone:
      return "none";
    case Role::kRead:
      return "read";
    case Role::kControl:
      return "control";
    case Role::kPublish:
      return "publish";
  }
  return "none";
}

Result<Role> parse_role(std::string_view name) {
  if (name == "none") return Role::kNone;
  if (name == "read") return Role::kRead;
  if (name == "control") return Role::kControl;
  if (name == "publish") return Role::kPublish;
  return make_error("unknown role '" + std::string(name) + "' (expected none, read, control or publish)");
}

Result<Credentials> Credentials::parse(std::string_view text, const std::string& source) {
  Credentials out;
  int line_number = 0;
  std::size_t start = 0;
  while (start <= text.size()) {
    std::size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(start, end - start);
    start = end + 1;
    ++line_number;
    auto fail = [&](const std::string& what) {
      Error e = make_error(ErrorKind::kInvalidData, what);
      e.file = source;
      e.line = line_number;
      return e;
    };
    std::size_t pos = 0;
    const std::string_view role_word = next_word(line, pos);
    if (role_word.empty() || role_word.front() == '#') continue;
    auto role = parse_role(role_word);
    if (!role.ok() || *role == Role::kNone) {
      return fail("unknown role '" + std::string(role_word).substr(0, 32) +
                  "': a line is 'read TOKEN', 'control TOKEN' or 'publish TOKEN'");
    }
    const std::string_view token = next_word(line, pos);
    if (token.empty() || token.front() == '#') return fail("a '" + std::string(role_word) + "' line without its token");
    if (token.size() < kMinTokenLength) {
      return fail("a token of " + std::to_string(token.size()) + " characters; tokens have at least " +
                  std::to_string(kMinTokenLength) + " (openssl rand -hex 16 makes one)");
    }
    const std::string_view rest = next_word(line, pos);
    if (!rest.empty() && rest.front() != '#') return fail("text after the token that is not a # comment");
    const auto digest = sha256(token);
    for (const Entry& e : out.entries_) {
      if (e.digest == digest) return fail("a token listed twice");
    }
    out.entries_.push_back(Entry{digest, *role});
  }
  if (out.entries_.empty()) {
    Error e = make_error(ErrorKind::kInvalidData, "no tokens: every client would be anonymous");
    e.file = source;
    return e;
  }
  return out;
}

Result<Credentials> Credentials::load(const std::string& path, std::string* warning) {
  auto text = read_file(path);
  if (!text.ok()) return text.error();
  struct stat st {};
  if (warning != nullptr && ::stat(path.c_str(), &st) == 0 && (st.st_mode & (S_IRWXG | S_IRWXO)) != 0) {
    *warning = "the auth file " + path + " can be read by other users (chmod 600 it): its tokens are passwords";
  }
  return parse(*text, path);
}

Role Credentials::role_of(std::string_view token) const {
  // Every entry is compared, whatever matched: the time taken is the same
  // for every token of a given file.
  const auto digest = sha256(token);
  Role found = Role::kNone;
  for (const Entry& e : entries_) {
    const bool match = CRYPTO_memcmp(e.digest.data(), digest.data(), digest.size()) == 0;
    found = match ? e.role : found;
  }
  return found;
}

}  // namespace gmr::server
