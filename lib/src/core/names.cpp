#include "gmr/core/names.h"

#include <cstdint>
#include <optional>

namespace gmr {

namespace {

// The code point starting at text[i] and its length in bytes; nullopt when
// the bytes there are not UTF-8 (overlong forms and surrogates included).
struct Decoded {
  char32_t c;
  std::size_t length;
};
std::optional<Decoded> decode(std::string_view text, std::size_t i) {
  const auto b0 = static_cast<unsigned char>(text[i]);
  if (b0 < 0x80) return Decoded{b0, 1};
  std::size_t n = 0;
  char32_t c = 0, min = 0;
  if ((b0 & 0xE0) == 0xC0) {
    n = 2, c = b0 & 0x1F, min = 0x80;
  } else if ((b0 & 0xF0) == 0xE0) {
    n = 3, c = b0 & 0x0F, min = 0x800;
  } else if ((b0 & 0xF8) == 0xF0) {
    n = 4, c = b0 & 0x07, min = 0x10000;
  } else {
    return std::nullopt;
  }
  if (i + n > text.size()) return std::nullopt;
  for (std::size_t k = 1; k < n; ++k) {
    const auto b = static_cast<unsigned char>(text[i + k]);
    if ((b & 0xC0) != 0x80) return std::nullopt;
    c = (c << 6) | (b & 0x3F);
  }
  if (c < min || c > 0x10FFFF || (c >= 0xD800 && c <= 0xDFFF)) return std::nullopt;
  return Decoded{c, n};
}

bool control(char32_t c) { return c < 0x20 || (c >= 0x7F && c <= 0x9F); }

// Invisible or look-alike: format characters and spaces other than U+0020.
bool deceptive(char32_t c) {
  return c == 0x00A0 || c == 0x00AD || c == 0x034F || c == 0x061C || c == 0x115F || c == 0x1160 || c == 0x1680 ||
         c == 0x17B4 || c == 0x17B5 || c == 0x180E || (c >= 0x2000 && c <= 0x200F) || (c >= 0x2028 && c <= 0x202F) ||
         (c >= 0x205F && c <= 0x206F) || c == 0x3000 || c == 0x3164 || c == 0xFEFF || c == 0xFFA0 ||
         (c >= 0xFFF9 && c <= 0xFFFB) || (c >= 0xE0000 && c <= 0xE007F);
}

std::string code_point(char32_t c) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string digits;
  // At least four digits, as Unicode writes them (U+001B, U+E0001, U+10FFFF).
  const int first = c > 0xFFFFF ? 20 : c > 0xFFFF ? 16 : 12;
  for (int shift = first; shift >= 0; shift -= 4) digits += kHex[(c >> shift) & 15];
  return "U+" + digits;
}

}  // namespace

std::string name_problem(std::string_view name, std::size_t max_bytes) {
  if (name.empty()) return "the name is empty";
  if (name.size() > max_bytes) {
    return "a name of " + std::to_string(name.size()) + " bytes; at most " + std::to_string(max_bytes);
  }
  if (name.front() == ' ' || name.back() == ' ') return "the name starts or ends with a space";
  for (std::size_t i = 0; i < name.size();) {
    const auto d = decode(name, i);
    if (!d) return "the name is not UTF-8 (byte " + std::to_string(i) + ")";
    if (control(d->c))
      return "the name has a control character (" + code_point(d->c) + ", byte " + std::to_string(i) + ")";
    if (deceptive(d->c)) {
      return "the name has an invisible or look-alike character (" + code_point(d->c) + ", byte " + std::to_string(i) +
             ")";
    }
    i += d->length;
  }
  return {};
}

std::string terminal_safe(std::string_view text) {
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size();) {
    const auto d = decode(text, i);
    if (!d) {
      const auto b = static_cast<unsigned char>(text[i]);
      out += "\\x";
      out += kHex[b >> 4];
      out += kHex[b & 15];
      ++i;
      continue;
    }
    if (d->c == '\n') {
      out += "\\n";
    } else if (d->c == '\t') {
      out += "\\t";
    } else if (d->c < 0x80 && control(d->c)) {
      out += "\\x";
      out += kHex[d->c >> 4];
      out += kHex[d->c & 15];
    } else if (control(d->c) || deceptive(d->c)) {
      std::string hex;
      for (char32_t c = d->c; c != 0; c >>= 4) hex.insert(hex.begin(), kHex[c & 15]);
      out += "\\u{" + hex + "}";
    } else {
      out.append(text.substr(i, d->length));
    }
    i += d->length;
  }
  return out;
}

}  // namespace gmr
