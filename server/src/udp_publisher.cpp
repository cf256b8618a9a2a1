#include "udp_publisher.h"

#include <spdlog/spdlog.h>

#include <sys/random.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>

#include "gmr/wire/udp.h"

namespace gmr::server {

UdpPublisher::UdpPublisher(net::io_context& io, std::size_t max_in_flight)
    : socket_(io), max_in_flight_(max_in_flight) {}

void UdpPublisher::open(const net::ip::address& address, std::uint16_t port) {
  const udp::endpoint ep(address, port);
  boost::system::error_code ec;
  socket_.open(ep.protocol(), ec);
  if (!ec) socket_.bind(ep, ec);
  if (ec) {
    throw std::runtime_error("cannot bind UDP " + address.to_string() + ":" + std::to_string(port) + ": " +
                             ec.message());
  }
  port_ = socket_.local_endpoint().port();
}

void UdpPublisher::start() { receive(); }

void UdpPublisher::close() {
  closed_ = true;
  boost::system::error_code ec;
  socket_.close(ec);
}

namespace {

// 16 bytes from the kernel's CSPRNG. getrandom blocks only before the pool is
// first seeded at boot; it cannot fail otherwise for 16 bytes.
wire::UdpToken random_token() {
  wire::UdpToken t{};
  std::size_t got = 0;
  while (got < t.size()) {
    const ssize_t n = ::getrandom(t.data() + got, t.size() - got, 0);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw std::runtime_error(std::string("getrandom failed: ") + std::strerror(errno));
    }
    got += static_cast<std::size_t>(n);
  }
  return t;
}

std::uint64_t key_of(const wire::UdpToken& t) {
  std::uint64_t k = 0;
  std::memcpy(&k, t.data(), sizeof k);
  return k;
}

}  // namespace

wire::UdpToken UdpPublisher::add_session(OnRegister on_register) {
  wire::UdpToken token;
  do {
    token = random_token();
  } while (sessions_.count(key_of(token)) != 0);
  sessions_.emplace(key_of(token), Session{token, std::move(on_register), std::nullopt, {}});
  return token;
}

void UdpPublisher::remove_session(const wire::UdpToken& token) {
  if (find(token) != nullptr) sessions_.erase(key_of(token));
}

UdpPublisher::Session* UdpPublisher::find(const wire::UdpToken& token) {
  auto it = sessions_.find(key_of(token));
  if (it == sessions_.end() || !wire::same_token(it->second.token, token)) return nullptr;
  return &it->second;
}

bool UdpPublisher::send(const std::shared_ptr<Registration>& to, std::string_view message) {
  if (closed_ || !to->endpoint) return false;
  auto datagrams = wire::fragment_message(to->next_message_id++, message);
  if (to->in_flight + datagrams.size() > max_in_flight_) return false;
  for (auto& d : datagrams) {
    auto held = std::make_shared<const std::string>(std::move(d));
    ++to->in_flight;
    socket_.async_send_to(net::buffer(*held), *to->endpoint,
                          [to, held](const boost::system::error_code&, std::size_t) { --to->in_flight; });
  }
  return true;
}

void UdpPublisher::receive() {
  socket_.async_receive_from(net::buffer(buffer_), sender_, [this](const boost::system::error_code& ec, std::size_t n) {
    if (ec == net::error::operation_aborted || closed_) return;
    if (!ec) handle(std::string_view(buffer_.data(), n));
    receive();
  });
}

void UdpPublisher::handle(std::string_view d) {
  const char* why = "not a registration or confirm datagram";
  if (const auto token = wire::parse_register_datagram(d)) {
    if (Session* s = find(*token)) {
      // One challenge per registration, no larger than it, to the address it
      // claims to come from: nothing else goes there until it is echoed.
      if (!s->challenged || *s->challenged != sender_) {
        s->challenged = sender_;
        s->cookie = random_token();
      }
      static_assert(wire::kChallengeBytes <= wire::kRegisterBytes);
      auto challenge = std::make_shared<const std::string>(wire::make_challenge_datagram(s->cookie));
      ++challenges_;
      socket_.async_send_to(net::buffer(*challenge), sender_,
                            [challenge](const boost::system::error_code&, std::size_t) {});
      return;
    }
    why = "unknown session token";
  } else if (const auto confirm = wire::parse_confirm_datagram(d)) {
    Session* s = find(confirm->token);
    if (s && s->challenged && *s->challenged == sender_ && wire::same_token(s->cookie, confirm->cookie)) {
      s->challenged.reset();
      s->cookie = random_token();  // a cookie confirms once
      s->on_register(sender_);
      return;
    }
    why = s ? "a confirm that answers no challenge sent to that address" : "unknown session token";
  }
  // Never answer: an address that proved nothing gets nothing from this server.
  if (rejected_++ % 1000 == 0) {
    spdlog::warn("ignoring a {}-byte UDP datagram from {}:{}: {} ({} so far)", d.size(), sender_.address().to_string(),
                 sender_.port(), why, rejected_);
  }
}

}  // namespace gmr::server
