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
#include "net.h"

namespace gmr::server {

class UdpPublisher {
 public:
  // Where one session's UDP frames go, once registered.
  struct Registration {
    std::optional<udp::endpoint> endpoint;
    std::size_t in_flight = 0;          // datagrams batched, not yet handed to the kernel
    std::uint32_t next_message_id = 0;  // fragments of one message share an id
  };
  using OnRegister = std::function<void(const udp::endpoint&)>;

  UdpPublisher(net::io_context& io, std::size_t max_in_flight);

  // Binds `address`:`port` (0: any free port). Throws std::runtime_error
  // naming the address when it cannot.
  void open(const net::ip::address& address, std::uint16_t port);
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

  // Sends a whole ServerMessage to `to` as fragments. False, sending
  // nothing, when `to` is not registered or already has max_in_flight
  // datagrams in flight.
  bool send(const std::shared_ptr<Registration>& to, std::string_view message);

  // sendmmsg calls made, and the datagrams they carried (a GSO message
  // counts its segments).
  std::uint64_t send_calls() const { return send_calls_; }
  std::uint64_t datagrams_sent() const { return datagrams_sent_; }

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
  // Consecutive fragments of one frame to one address: one sendmmsg entry
  // (a GSO message when `count` > 1).
  struct Batched {
    std::size_t offset = 0;  // into batch_bytes_
    std::size_t bytes = 0;
    std::size_t count = 0;   // datagrams
    udp::endpoint to;
    std::shared_ptr<Registration> registration;
  };
  void flush();
  // Gives the entries from `first` on back to their registrations, unsent.
  void release(std::size_t first);
  void clear_batch();
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
  std::uint64_t rejected_sends_ = 0;

  std::string batch_bytes_;
  std::vector<Batched> batch_;
  std::size_t batch_sent_ = 0;  // entries of batch_ already handed to the kernel
  bool flush_posted_ = false;
  bool awaiting_writable_ = false;
  bool gso_ = true;  // until the kernel refuses a GSO message
  std::uint64_t send_calls_ = 0;
  std::uint64_t datagrams_sent_ = 0;
};

}  // namespace gmr::server
