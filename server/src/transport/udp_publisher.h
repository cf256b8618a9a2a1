// UdpPublisher: the server's UDP socket. It takes registrations (a client
// proves it holds a session's token, then proves it owns the address that is
// to receive that session's frames by echoing a challenge sent there) and
// sends frames as fragments (gmr/wire/udp.h), with a bound on the datagrams
// in flight per registration. Tokens are 128 bits from getrandom(2).
//
// Frames are not sent one syscall each: send() appends a frame's fragments to
// a batch, and the batch goes out after the handlers already due have run
// (so one tick's fan-out is one batch) with sendmmsg(2), a frame's fragments
// as one UDP GSO message (UDP_SEGMENT) where the kernel takes it. A full
// socket buffer parks the batch until the socket is writable.
//
// Threads (io_threads.h): registrations are read and answered on the control
// loop. Sending has one sender per I/O thread (a duplicate of the socket's
// descriptor, so every datagram leaves from the one port): a registration
// is sent through its lane's sender (Registration::lane, its connection's),
// so the kernel's work for a frame runs on that lane while send() itself
// only appends, from the control loop, under the sender's lock.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "gmr/wire/udp.h"
#include "transport/io_threads.h"
#include "transport/net.h"
#include "transport/udp_sender.h"

namespace gmr::server {

class UdpPublisher {
 public:
  // Where one session's UDP frames go, once registered (udp_sender.h).
  using Registration = UdpRegistration;
  using OnRegister = std::function<void(const udp::endpoint&)>;

  UdpPublisher(net::io_context& io, std::size_t max_in_flight);
  ~UdpPublisher();

  // Binds `address`:`port` (0: any free port), with a sender on each of
  // `threads`' lanes (null: one sender on the control loop). Throws
  // std::runtime_error naming the address when it cannot.
  void open(const net::ip::address& address, std::uint16_t port, IoThreads* threads = nullptr);
  std::uint16_t port() const { return port_; }
  // Lets the socket send to IPv4 multicast `group`:`port` with `ttl`, out of
  // the interface of the bound address (unless it is any). Throws
  // std::runtime_error saying why not. Returns the group's registration, the
  // destination of every multicast frame.
  std::shared_ptr<Registration> open_multicast(const std::string& group, std::uint16_t port, int ttl);
  // Starts taking registrations.
  void start();
  void close();

  // A fresh session token (random, unique among the live ones). A
  // registration carrying it gets one challenge sent to its source address;
  // the confirm echoing that challenge from that address calls `on_register`.
  wire::UdpToken add_session(OnRegister on_register);
  void remove_session(const wire::UdpToken& token);

  // Sends a whole ServerMessage, `head` then `body`, to `to` as fragments,
  // through its lane's sender. False, sending nothing, when `to` is not
  // registered or already has max_in_flight datagrams in flight. Control
  // loop only.
  bool send(const std::shared_ptr<Registration>& to, std::string_view head, std::string_view body = {});
  // A frame: `head` (frame_head_for, no length prefix), its shared `body`,
  // then a write stamp set as its first datagram is handed to the kernel.
  bool send_frame(const std::shared_ptr<Registration>& to, std::string_view head, std::string_view body);

  // True when `to`'s sender (its I/O thread) has a datagram that has waited
  // longer than set_congested_after to be handed to the kernel: the thread
  // is behind, and streams skip computing frames for it (counting them
  // dropped) instead of piling them up. Control loop only.
  bool congested(const Registration& to) const;
  void set_congested_after(Clock::duration d) { congested_after_ = d; }

  // sendmmsg calls made, the datagrams they carried (a GSO message counts
  // its segments) and their payload bytes, all senders.
  std::uint64_t send_calls() const;
  std::uint64_t datagrams_sent() const;
  std::uint64_t bytes_sent() const;

  // Datagrams that were not a valid registration or confirm.
  std::uint64_t rejected() const { return rejected_; }
  // Challenges sent (one per valid registration datagram).
  std::uint64_t challenges() const { return challenges_; }

 private:
  struct Session {
    wire::UdpToken token{};
    OnRegister on_register;
    std::optional<udp::endpoint> challenged;  // the address a challenge went to, awaiting its confirm
    wire::UdpToken cookie{};
  };
  void receive();
  void handle(std::string_view datagram);
  // The live session holding `token` (constant-time compare), or null.
  Session* find(const wire::UdpToken& token);

  udp::socket socket_;
  std::size_t max_in_flight_;
  std::uint16_t port_ = 0;
  bool closed_ = false;
  std::unordered_map<std::uint64_t, Session> sessions_;  // by the token's first 8 bytes
  std::array<char, 2048> buffer_{};
  udp::endpoint sender_;
  std::uint64_t rejected_ = 0;
  std::uint64_t challenges_ = 0;

  std::vector<std::unique_ptr<UdpSender>> senders_;  // one per lane
  Clock::duration congested_after_ = std::chrono::milliseconds(50);
};

}  // namespace gmr::server
