// Private: shortest round-trip formatting of doubles, byte for byte what
// std::to_chars(first, last, value) writes, with a fast path for the short
// decimals motion files are made of.
#pragma once

#include <charconv>
#include <cmath>
#include <cstdint>

namespace gmr::detail {

// Writes the shortest text that reads back to exactly `v` into `out` (at
// least 32 bytes) and returns the end. Same bytes as std::to_chars(out, out +
// 32, v).
//
// Fast path: |v| = m / 10^k exactly (as the reader's fast path computes it)
// with m < 10^15 and the smallest such k. Then m is the only k-decimal number
// that reads back to v (10^-k is more than 4 ulps of v), and no decimal with
// fewer significant digits does (it would have fewer decimals), so m's digits
// are the shortest digits std::to_chars picks. The fixed form is used when it
// is not longer than the scientific one, which is std::to_chars' choice;
// otherwise, and for 0, inf, nan and long mantissas, std::to_chars writes it.
inline char* format_shortest(char* out, double v) {
  static constexpr double kPow10[] = {1e0, 1e1, 1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                      1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15};
  const double a = std::fabs(v);
  if (a >= 1e-6 && a < 1e15) {
    for (int k = 0; k < 16; ++k) {
      const double scaled = a * kPow10[k];
      if (scaled >= 1e15) break;
      const double r = std::nearbyint(scaled);
      // Cheap filter first: m / 10^k == a needs scaled within a few ulps of m.
      if (std::fabs(scaled - r) > scaled * 0x1p-49 || r / kPow10[k] != a) continue;
      std::uint64_t m = static_cast<std::uint64_t>(r);
      // Digits of m, least significant first.
      char digits[20];
      int n = 0;
      do {
        digits[n++] = static_cast<char>('0' + m % 10);
        m /= 10;
      } while (m != 0);
      // Fixed: "[-]int.frac" or "[-]0.000frac".
      const int fixed_len = (k == 0) ? n : (n > k ? n + 1 : k + 2);
      // Scientific: significant digits (no trailing zeros), "d[.ddd]e±XX".
      int trailing = 0;
      while (trailing < n - 1 && digits[trailing] == '0') ++trailing;
      const int sig = n - trailing;
      const int exponent = (n - 1) - k;
      const int sci_len = sig + (sig > 1 ? 1 : 0) + 2 + (std::abs(exponent) >= 100 ? 3 : 2);
      if (fixed_len > sci_len) break;  // std::to_chars writes the scientific form
      char* p = out;
      if (std::signbit(v)) *p++ = '-';
      if (k == 0) {
        for (int i = n - 1; i >= 0; --i) *p++ = digits[i];
      } else if (n > k) {
        for (int i = n - 1; i >= k; --i) *p++ = digits[i];
        *p++ = '.';
        for (int i = k - 1; i >= 0; --i) *p++ = digits[i];
      } else {
        *p++ = '0';
        *p++ = '.';
        for (int i = k - 1; i >= n; --i) *p++ = '0';
        for (int i = n - 1; i >= 0; --i) *p++ = digits[i];
      }
      return p;
    }
  }
  return std::to_chars(out, out + 32, v).ptr;
}

}  // namespace gmr::detail
