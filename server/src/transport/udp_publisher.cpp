#include "transport/udp_publisher.h"

#include <spdlog/spdlog.h>

#include <sys/random.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>

#include "gmr/wire/frames.h"
#include "gmr/wire/udp.h"

namespace gmr::server {

namespace {
// Datagrams read per pass of the event loop.
constexpr int kReceiveBatch = 64;
}  // namespace

UdpPublisher::UdpPublisher(net::io_context& io, std::size_t max_in_flight)
    : socket_(io), max_in_flight_(max_in_flight) {}

UdpPublisher::~UdpPublisher() = default;

void UdpPublisher::open(const net::ip::address& address, std::uint16_t port, IoThreads* threads) {
  const udp::endpoint ep(address, port);
  boost::system::error_code ec;
  socket_.open(ep.protocol(), ec);
  if (!ec) socket_.bind(ep, ec);
  if (ec) {
    throw std::runtime_error("cannot bind UDP " + address.to_string() + ":" + std::to_string(port) + ": " +
                             ec.message());
  }
  port_ = socket_.local_endpoint().port();
  // Reads past the first datagram of a pass (receive()) must not block.
  socket_.non_blocking(true, ec);
  if (threads == nullptr) {
    senders_.push_back(std::make_unique<UdpSender>(static_cast<net::io_context&>(socket_.get_executor().context()),
                                                   socket_, max_in_flight_, nullptr, 0));
    return;
  }
  for (std::size_t lane = 0; lane < threads->size(); ++lane) {
    senders_.push_back(std::make_unique<UdpSender>(threads->io(lane), socket_, max_in_flight_, threads, lane));
  }
}

std::shared_ptr<UdpPublisher::Registration> UdpPublisher::open_multicast(const std::string& group, std::uint16_t port,
                                                                         int ttl) {
  boost::system::error_code ec;
  const auto address = net::ip::make_address_v4(group, ec);
  if (ec || !address.is_multicast()) {
    throw std::runtime_error("--multicast-group " + group + " is not an IPv4 multicast address (224.0.0.0/4)");
  }
  if (ttl < 0 || ttl > 255) throw std::runtime_error("--multicast-ttl must be within [0, 255]");
  const auto local = socket_.local_endpoint(ec).address();
  if (local.is_v4()) {
    socket_.set_option(net::ip::multicast::hops(ttl), ec);
    if (!ec && !local.is_unspecified()) socket_.set_option(net::ip::multicast::outbound_interface(local.to_v4()), ec);
    if (!ec) socket_.set_option(net::ip::multicast::enable_loopback(true), ec);
  } else {
    ec = net::error::address_family_not_supported;
  }
  if (ec) {
    throw std::runtime_error("cannot send multicast to " + group + " from the UDP socket (" + local.to_string() +
                             "): " + ec.message());
  }
  if (const auto why = multicast_unreachable(local, address); !why.empty()) {
    spdlog::warn("multicast streams will reach no one: {}", why);
  }
  auto r = std::make_shared<Registration>();
  r->endpoint = udp::endpoint(address, port);
  return r;
}

void UdpPublisher::start() { receive(); }

void UdpPublisher::close() {
  closed_ = true;
  boost::system::error_code ec;
  socket_.close(ec);
  for (auto& s : senders_) s->close();
}

std::uint64_t UdpPublisher::send_calls() const {
  std::uint64_t n = 0;
  for (const auto& s : senders_) n += s->send_calls();
  return n;
}

std::uint64_t UdpPublisher::datagrams_sent() const {
  std::uint64_t n = 0;
  for (const auto& s : senders_) n += s->datagrams_sent();
  return n;
}

std::uint64_t UdpPublisher::bytes_sent() const {
  std::uint64_t n = 0;
  for (const auto& s : senders_) n += s->bytes_sent();
  return n;
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

bool UdpPublisher::congested(const Registration& to) const {
  return to.lane < senders_.size() && senders_[to.lane]->backlog() > congested_after_;
}

bool UdpPublisher::send(const std::shared_ptr<Registration>& to, std::string_view head, std::string_view body) {
  if (closed_ || to->lane >= senders_.size()) return false;
  return senders_[to->lane]->send(to, head, body, false);
}

bool UdpPublisher::send_frame(const std::shared_ptr<Registration>& to, std::string_view head, std::string_view body) {
  if (closed_ || to->lane >= senders_.size()) return false;
  return senders_[to->lane]->send(to, head, body, true);
}

void UdpPublisher::receive() {
  socket_.async_receive_from(net::buffer(buffer_), sender_, [this](const boost::system::error_code& ec, std::size_t n) {
    if (ec == net::error::operation_aborted || closed_) return;
    if (!ec) handle(std::string_view(buffer_.data(), n));
    // Whatever else is waiting, now: a server busy fanning frames out runs
    // this handler once per pass of its event loop, and registrations
    // arriving faster than that would otherwise time out in the queue.
    for (int more = 0; more < kReceiveBatch && !closed_; ++more) {
      boost::system::error_code again;
      const std::size_t m = socket_.receive_from(net::buffer(buffer_), sender_, 0, again);
      if (again) break;
      handle(std::string_view(buffer_.data(), m));
    }
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
