// UDP datagrams. Every datagram starts with the same 8 bytes:
//
//   0       4         5      6        8
//   +-------+---------+------+--------+
//   | "GMRU"| version | kind | 0 0    |
//   +-------+---------+------+--------+
//
// kind 1, register (client -> server), 24 bytes: header + the 16-byte
//   session token the client got in HelloReply.udp_token over TCP.
// kind 3, challenge (server -> the registering address), 24 bytes: header +
//   a 16-byte random cookie. Never larger than the registration it answers:
//   a forged source address gets at most as many bytes as the forger sent.
// kind 4, confirm (client -> server), 40 bytes: header + token + cookie,
//   from the address that was challenged. Only then does the server send
//   that session's frames there (the QUIC/DTLS cookie idea).
// kind 2, fragment (server -> client): header + message id (uint32), fragment
//   index (uint16), fragment count (uint16), total size (uint32), then the
//   fragment's bytes. The fragments of one message, in index order, are one
//   serialized ServerMessage (a Frame). Every fragment but the last carries
//   exactly kMaxFragmentPayload bytes. A message with a missing fragment is
//   dropped whole.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace gmr::wire {

inline constexpr std::uint8_t kUdpVersion = 2;  // 1 had 8-byte tokens and no challenge
inline constexpr std::size_t kUdpHeaderBytes = 8;
inline constexpr std::size_t kUdpTokenBytes = 16;
using UdpToken = std::array<std::uint8_t, kUdpTokenBytes>;
inline constexpr std::size_t kRegisterBytes = kUdpHeaderBytes + kUdpTokenBytes;
inline constexpr std::size_t kChallengeBytes = kUdpHeaderBytes + kUdpTokenBytes;
inline constexpr std::size_t kConfirmBytes = kUdpHeaderBytes + 2 * kUdpTokenBytes;
inline constexpr std::size_t kFragmentHeaderBytes = kUdpHeaderBytes + 12;
// Each datagram stays under the ~1280-byte IPv6 minimum MTU minus IP/UDP headers.
inline constexpr std::size_t kMaxDatagramBytes = 1200;
inline constexpr std::size_t kMaxFragmentPayload = kMaxDatagramBytes - kFragmentHeaderBytes;
// Largest message a fragment header may announce (bounds reassembly memory).
inline constexpr std::uint32_t kMaxUdpMessageBytes = 1u << 20;

enum class DatagramKind : std::uint8_t { kRegister = 1, kFragment = 2, kChallenge = 3, kConfirm = 4 };

// The registration datagram for `token`, and its token when well-formed.
std::string make_register_datagram(const UdpToken& token);
std::optional<UdpToken> parse_register_datagram(std::string_view datagram);
// The challenge carrying `cookie`, and its cookie when well-formed.
std::string make_challenge_datagram(const UdpToken& cookie);
std::optional<UdpToken> parse_challenge_datagram(std::string_view datagram);
// The confirmation of a challenge, and its two halves when well-formed.
struct UdpConfirm {
  UdpToken token{};
  UdpToken cookie{};
};
std::string make_confirm_datagram(const UdpToken& token, const UdpToken& cookie);
std::optional<UdpConfirm> parse_confirm_datagram(std::string_view datagram);
// Equality in constant time: no early exit at the first differing byte, so
// timing tells an attacker nothing about how much of a guess was right.
bool same_token(const UdpToken& a, const UdpToken& b);

// Splits `message` into datagrams (at least one, even for an empty message).
// Requires message.size() <= kMaxUdpMessageBytes.
std::vector<std::string> fragment_message(std::uint32_t message_id, std::string_view message);
// How many datagrams a message of `message_bytes` takes (at least one).
inline std::size_t fragment_count(std::size_t message_bytes) {
  return message_bytes == 0 ? 1 : (message_bytes + kMaxFragmentPayload - 1) / kMaxFragmentPayload;
}
// The same datagrams appended back to back to `out`, for a sender that
// batches them: every one but the last is exactly kMaxDatagramBytes long.
// Returns how many there are.
std::size_t append_fragments(std::string& out, std::uint32_t message_id, std::string_view message);
// The same for a message in two pieces, `first` then `rest` (a frame's own
// head and the body its stream shares), without joining them first.
std::size_t append_fragments(std::string& out, std::uint32_t message_id, std::string_view first, std::string_view rest);

// Rebuilds messages from fragments that may arrive late, twice, out of order
// or not at all. Keeps at most kMaxPartial messages in progress; starting one
// more drops the oldest incomplete one whole. Memory is bounded by
// kMaxPartial * kMaxUdpMessageBytes.
class Reassembler {
 public:
  static constexpr std::size_t kMaxPartial = 8;

  // Feeds one datagram. Returns the whole message when this datagram completed
  // one. Malformed datagrams are counted and ignored.
  std::optional<std::string> add(std::string_view datagram);

  std::uint64_t completed() const { return completed_; }
  std::uint64_t dropped() const { return dropped_; }      // messages given up incomplete
  std::uint64_t malformed() const { return malformed_; }  // datagrams that were not valid fragments

 private:
  struct Partial {
    std::uint32_t id = 0;
    std::uint16_t count = 0;
    std::uint32_t total = 0;
    std::uint16_t received = 0;
    std::vector<bool> have;
    std::string bytes;
  };
  std::deque<Partial> partial_;
  std::deque<std::uint32_t> recent_done_;  // ids completed lately: a duplicate fragment must not restart them
  std::uint64_t completed_ = 0;
  std::uint64_t dropped_ = 0;
  std::uint64_t malformed_ = 0;
};

}  // namespace gmr::wire
