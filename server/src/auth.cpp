#include "gmr/server/auth.h"

#include <openssl/crypto.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>

#include "gmr/core/file_util.h"
#include "transport/digest.h"

namespace gmr::server {

namespace {

constexpr double kMinTokenBits = 128;
constexpr std::size_t kMinDistinct = 8;

// Why `token` is too weak to guard a server (empty: it is not). Its
// strength is estimated as a random string over the character classes it
// uses (digits 10, lower case 26, upper case 26, other printable 33):
// `openssl rand -hex 16` (32 characters of 36) has 165 bits, 16 characters
// of lower case 75. A token of fewer than 8 distinct characters is refused
// whatever its length (aaaa...).
std::string weak_token(std::string_view token) {
  bool digit = false, lower = false, upper = false, other = false;
  std::array<bool, 256> seen{};
  std::size_t distinct = 0;
  for (const char ch : token) {
    const auto c = static_cast<unsigned char>(ch);
    digit |= c >= '0' && c <= '9';
    lower |= c >= 'a' && c <= 'z';
    upper |= c >= 'A' && c <= 'Z';
    other |= !std::isalnum(c);
    if (!seen[c]) ++distinct, seen[c] = true;
  }
  const double alphabet = (digit ? 10 : 0) + (lower ? 26 : 0) + (upper ? 26 : 0) + (other ? 33 : 0);
  const double bits = static_cast<double>(token.size()) * std::log2(std::max(alphabet, 2.0));
  if (bits < kMinTokenBits || distinct < kMinDistinct) {
    char text[200];
    std::snprintf(text, sizeof text,
                  "a weak token (%zu characters, %zu distinct, about %.0f bits; at least %.0f bits and %zu distinct: "
                  "openssl rand -hex 16 makes one)",
                  token.size(), distinct, bits, kMinTokenBits, kMinDistinct);
    return text;
  }
  return {};
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
    if (token.size() > kMaxTokenBytes) {
      return fail("a token of " + std::to_string(token.size()) + " characters; at most " +
                  std::to_string(kMaxTokenBytes));
    }
    if (const std::string why = weak_token(token); !why.empty()) return fail(why);
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
  // Longer than any token can be: refused before it is hashed (a 4 MiB
  // "token" took 8 ms of SHA-256).
  if (token.size() > kMaxTokenBytes) return Role::kNone;
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
