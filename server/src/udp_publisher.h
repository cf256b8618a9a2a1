// UdpPublisher: the server's UDP socket. It takes registrations (a client
// proves it holds a session's token, then proves it owns the address that is
// to receive that session's frames by echoing a challenge sent there) and
// sends frames as fragments (gmr/wire/udp.h), with a bound on the datagrams
// in flight per registration. Tokens are 128 bits from getrandom(2).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string_view>
#include <unordered_map>

#include "gmr/wire/udp.h"
#include "net.h"

namespace gmr::server {

class UdpPublisher {
 public:
  // Where one session's UDP frames go, once registered.
  struct Registration {
    std::optional<udp::endpoint> endpoint;
    std::size_t in_flight = 0;          // datagrams handed to the kernel, not yet sent
    std::uint32_t next_message_id = 0;  // fragments of one message share an id
  };
  using OnRegister = std::function<void(const udp::endpoint&)>;

  UdpPublisher(net::io_context& io, std::size_t max_in_flight);

  // Binds `address`:`port` (0: any free port). Throws std::runtime_error
  // naming the address when it cannot.
  void open(const net::ip::address& address, std::uint16_t port);
  std::uint16_t port() const { return port_; }
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
};

}  // namespace gmr::server
