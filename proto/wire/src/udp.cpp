#include "gmr/wire/udp.h"

#include <algorithm>
#include <array>
#include <cstring>

namespace gmr::wire {
namespace {

constexpr char kMagic[4] = {'G', 'M', 'R', 'U'};

void put_header(std::string& out, DatagramKind kind) {
  out.append(kMagic, 4);
  out.push_back(static_cast<char>(kUdpVersion));
  out.push_back(static_cast<char>(kind));
  out.append(2, '\0');
}

// `v` big-endian at `out`.
template <class T>
void put_be(char* out, T v) {
  for (std::size_t i = 0; i < sizeof(T); ++i) {
    out[i] = static_cast<char>(static_cast<std::uint8_t>(v >> (8 * (sizeof(T) - 1 - i))));
  }
}

template <class T>
T get_be(std::string_view in, std::size_t at) {
  T v = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) v = static_cast<T>((v << 8) | static_cast<std::uint8_t>(in[at + i]));
  return v;
}

bool header_is(std::string_view d, DatagramKind kind) {
  return d.size() >= kUdpHeaderBytes && std::memcmp(d.data(), kMagic, 4) == 0 &&
         static_cast<std::uint8_t>(d[4]) == kUdpVersion &&
         static_cast<std::uint8_t>(d[5]) == static_cast<std::uint8_t>(kind);
}

void put_token(std::string& out, const UdpToken& t) { out.append(reinterpret_cast<const char*>(t.data()), t.size()); }

UdpToken get_token(std::string_view in, std::size_t at) {
  UdpToken t;
  std::memcpy(t.data(), in.data() + at, t.size());
  return t;
}

std::string token_datagram(DatagramKind kind, const UdpToken& token) {
  std::string out;
  out.reserve(kUdpHeaderBytes + kUdpTokenBytes);
  put_header(out, kind);
  put_token(out, token);
  return out;
}

}  // namespace

std::string make_register_datagram(const UdpToken& token) { return token_datagram(DatagramKind::kRegister, token); }

std::optional<UdpToken> parse_register_datagram(std::string_view d) {
  if (d.size() != kRegisterBytes || !header_is(d, DatagramKind::kRegister)) return std::nullopt;
  return get_token(d, kUdpHeaderBytes);
}

std::string make_challenge_datagram(const UdpToken& cookie) { return token_datagram(DatagramKind::kChallenge, cookie); }

std::optional<UdpToken> parse_challenge_datagram(std::string_view d) {
  if (d.size() != kChallengeBytes || !header_is(d, DatagramKind::kChallenge)) return std::nullopt;
  return get_token(d, kUdpHeaderBytes);
}

std::string make_confirm_datagram(const UdpToken& token, const UdpToken& cookie) {
  std::string out = token_datagram(DatagramKind::kConfirm, token);
  put_token(out, cookie);
  return out;
}

std::optional<UdpConfirm> parse_confirm_datagram(std::string_view d) {
  if (d.size() != kConfirmBytes || !header_is(d, DatagramKind::kConfirm)) return std::nullopt;
  return UdpConfirm{get_token(d, kUdpHeaderBytes), get_token(d, kUdpHeaderBytes + kUdpTokenBytes)};
}

bool same_token(const UdpToken& a, const UdpToken& b) {
  // volatile: the compiler may not turn the loop into an early-exit compare.
  volatile std::uint8_t diff = 0;
  for (std::size_t i = 0; i < a.size(); ++i) diff = static_cast<std::uint8_t>(diff | (a[i] ^ b[i]));
  return diff == 0;
}

std::size_t append_fragments(std::string& out, std::uint32_t message_id, std::string_view message) {
  return append_fragments(out, message_id, message, std::string_view());
}

std::size_t append_fragments(std::string& out, std::uint32_t message_id, std::string_view first,
                             std::string_view rest) {
  const std::size_t total = first.size() + rest.size();
  const std::size_t count = fragment_count(total);
  out.reserve(out.size() + count * kFragmentHeaderBytes + total);
  // Bytes [from, from + n) of first + rest.
  auto append_range = [&](std::size_t from, std::size_t n) {
    if (from < first.size()) {
      const std::size_t k = std::min(n, first.size() - from);
      out.append(first.substr(from, k));
      from += k;
      n -= k;
    }
    if (n > 0) out.append(rest.substr(from - first.size(), n));
  };
  // The header is the same for every fragment but its index: made once, in
  // place, and appended whole (a sender appends one per subscriber and
  // frame, so byte-by-byte appends showed in its profile).
  std::array<char, kFragmentHeaderBytes> header{};
  std::memcpy(header.data(), kMagic, 4);
  header[4] = static_cast<char>(kUdpVersion);
  header[5] = static_cast<char>(DatagramKind::kFragment);
  put_be(header.data() + kUdpHeaderBytes, message_id);
  put_be(header.data() + kUdpHeaderBytes + 6, static_cast<std::uint16_t>(count));
  put_be(header.data() + kUdpHeaderBytes + 8, static_cast<std::uint32_t>(total));
  for (std::size_t i = 0; i < count; ++i) {
    put_be(header.data() + kUdpHeaderBytes + 4, static_cast<std::uint16_t>(i));
    out.append(header.data(), header.size());
    const std::size_t from = std::min(total, i * kMaxFragmentPayload);
    append_range(from, std::min(kMaxFragmentPayload, total - from));
  }
  return count;
}

std::vector<std::string> fragment_message(std::uint32_t message_id, std::string_view message) {
  std::string all;
  const std::size_t count = append_fragments(all, message_id, message);
  std::vector<std::string> out;
  out.reserve(count);
  for (std::size_t i = 0; i < count; ++i) out.push_back(all.substr(i * kMaxDatagramBytes, kMaxDatagramBytes));
  return out;
}

std::optional<std::string> Reassembler::add(std::string_view d) {
  if (d.size() < kFragmentHeaderBytes || !header_is(d, DatagramKind::kFragment)) {
    ++malformed_;
    return std::nullopt;
  }
  const auto id = get_be<std::uint32_t>(d, kUdpHeaderBytes);
  const auto index = get_be<std::uint16_t>(d, kUdpHeaderBytes + 4);
  const auto count = get_be<std::uint16_t>(d, kUdpHeaderBytes + 6);
  const auto total = get_be<std::uint32_t>(d, kUdpHeaderBytes + 8);
  const std::string_view payload = d.substr(kFragmentHeaderBytes);
  // The header must describe a consistent message: count matches total, the
  // fragment has exactly the size its index implies.
  const std::size_t expect_count = std::max<std::size_t>(1, (total + kMaxFragmentPayload - 1) / kMaxFragmentPayload);
  const std::size_t expect_size = index + 1u < count
                                      ? kMaxFragmentPayload
                                      : total - std::min<std::size_t>(total, std::size_t{index} * kMaxFragmentPayload);
  if (total > kMaxUdpMessageBytes || count != expect_count || index >= count || payload.size() != expect_size) {
    ++malformed_;
    return std::nullopt;
  }
  if (std::find(recent_done_.begin(), recent_done_.end(), id) != recent_done_.end()) return std::nullopt;

  auto done = [&](std::string bytes) {
    ++completed_;
    recent_done_.push_back(id);
    if (recent_done_.size() > 4 * kMaxPartial) recent_done_.pop_front();
    return std::optional<std::string>(std::move(bytes));
  };
  if (count == 1) return done(std::string(payload));

  auto it = std::find_if(partial_.begin(), partial_.end(), [&](const Partial& p) { return p.id == id; });
  if (it == partial_.end()) {
    if (partial_.size() == kMaxPartial) {
      partial_.pop_front();
      ++dropped_;
    }
    Partial p;
    p.id = id;
    p.count = count;
    p.total = total;
    p.have.assign(count, false);
    p.bytes.assign(total, '\0');
    partial_.push_back(std::move(p));
    it = partial_.end() - 1;
  } else if (it->count != count || it->total != total) {
    ++malformed_;  // same id, different shape: not ours to trust
    return std::nullopt;
  }
  if (it->have[index]) return std::nullopt;  // duplicate
  it->have[index] = true;
  ++it->received;
  std::memcpy(it->bytes.data() + std::size_t{index} * kMaxFragmentPayload, payload.data(), payload.size());
  if (it->received < it->count) return std::nullopt;
  std::string bytes = std::move(it->bytes);
  partial_.erase(it);
  return done(std::move(bytes));
}

}  // namespace gmr::wire
