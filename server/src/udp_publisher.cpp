#include "udp_publisher.h"

#include <spdlog/spdlog.h>

#include <netinet/udp.h>
#include <sys/random.h>
#include <sys/socket.h>

#include <algorithm>
#include <array>
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
  // Reads past the first datagram of a pass (receive()) must not block.
  socket_.non_blocking(true, ec);
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
  auto r = std::make_shared<Registration>();
  r->endpoint = udp::endpoint(address, port);
  return r;
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

#ifndef UDP_SEGMENT
#define UDP_SEGMENT 103  // linux/udp.h, for C libraries that predate it
#endif

namespace {

// UDP GSO limits: at most 64 segments, and the whole message within one
// IP datagram's 64 KiB.
constexpr std::size_t kMaxGsoSegments = std::min<std::size_t>(64, 65000 / wire::kMaxDatagramBytes);
// Entries per sendmmsg call (the kernel caps a call at UIO_MAXIOV, 1024).
constexpr std::size_t kSendBatch = 256;
// Datagrams read per pass of the event loop.
constexpr int kReceiveBatch = 64;

}  // namespace

bool UdpPublisher::send(const std::shared_ptr<Registration>& to, std::string_view message) {
  if (closed_ || !to->endpoint) return false;
  if (to->in_flight + wire::fragment_count(message.size()) > max_in_flight_) return false;
  std::size_t at = batch_bytes_.size();
  const std::size_t appended = wire::append_fragments(batch_bytes_, to->next_message_id++, message);
  const std::size_t end = batch_bytes_.size();
  // Without GSO every datagram is its own entry; with it, runs of up to
  // kMaxGsoSegments share one.
  const std::size_t per_entry = gso_ ? kMaxGsoSegments : 1;
  for (std::size_t done = 0; done < appended;) {
    const std::size_t n = std::min(per_entry, appended - done);
    const std::size_t bytes = std::min(n * wire::kMaxDatagramBytes, end - at);
    batch_.push_back(Batched{at, bytes, n, *to->endpoint, to});
    at += bytes;
    done += n;
  }
  to->in_flight += appended;
  if (!flush_posted_ && !awaiting_writable_) {
    flush_posted_ = true;
    net::post(socket_.get_executor(), [this] {
      flush_posted_ = false;
      flush();
    });
  }
  return true;
}

void UdpPublisher::release(std::size_t first) {
  for (std::size_t i = first; i < batch_.size(); ++i) batch_[i].registration->in_flight -= batch_[i].count;
}

void UdpPublisher::flush() {
  if (closed_) {
    release(batch_sent_);
    clear_batch();
    return;
  }
  std::array<mmsghdr, kSendBatch> msgs;
  std::array<iovec, kSendBatch> iovs;
  alignas(cmsghdr) std::array<char, kSendBatch * CMSG_SPACE(sizeof(std::uint16_t))> controls;
  const int fd = socket_.native_handle();
  while (batch_sent_ < batch_.size()) {
    const std::size_t n = std::min(kSendBatch, batch_.size() - batch_sent_);
    for (std::size_t i = 0; i < n; ++i) {
      Batched& b = batch_[batch_sent_ + i];
      iovs[i] = iovec{batch_bytes_.data() + b.offset, b.bytes};
      msghdr& h = msgs[i].msg_hdr;
      h = msghdr{};
      h.msg_name = b.to.data();
      h.msg_namelen = static_cast<socklen_t>(b.to.size());
      h.msg_iov = &iovs[i];
      h.msg_iovlen = 1;
      if (b.count > 1) {
        char* control = controls.data() + i * CMSG_SPACE(sizeof(std::uint16_t));
        h.msg_control = control;
        h.msg_controllen = CMSG_SPACE(sizeof(std::uint16_t));
        cmsghdr* c = CMSG_FIRSTHDR(&h);
        c->cmsg_level = SOL_UDP;
        c->cmsg_type = UDP_SEGMENT;
        c->cmsg_len = CMSG_LEN(sizeof(std::uint16_t));
        const auto segment = static_cast<std::uint16_t>(wire::kMaxDatagramBytes);
        std::memcpy(CMSG_DATA(c), &segment, sizeof segment);
      }
    }
    const int sent = ::sendmmsg(fd, msgs.data(), static_cast<unsigned>(n), MSG_DONTWAIT);
    ++send_calls_;
    if (sent > 0) {
      for (int i = 0; i < sent; ++i) {
        Batched& b = batch_[batch_sent_ + static_cast<std::size_t>(i)];
        b.registration->in_flight -= b.count;
        datagrams_sent_ += b.count;
      }
      batch_sent_ += static_cast<std::size_t>(sent);
      continue;
    }
    const int err = sent < 0 ? errno : EAGAIN;
    if (err == EINTR) continue;
    if (err == EAGAIN || err == EWOULDBLOCK || err == ENOBUFS) {
      // The socket buffer is full: the rest goes when the kernel has room.
      awaiting_writable_ = true;
      socket_.async_wait(udp::socket::wait_write, [this](const boost::system::error_code& ec) {
        awaiting_writable_ = false;
        if (ec == net::error::operation_aborted) closed_ = true;
        flush();
      });
      return;
    }
    // The first entry failed on its own (an address the kernel will not send
    // to, or a GSO message the device cannot segment): it is lost, as any
    // datagram may be, and the rest still go.
    Batched& b = batch_[batch_sent_];
    if (b.count > 1 && (err == EIO || err == EINVAL || err == ENOPROTOOPT)) {
      if (gso_) {
        gso_ = false;
        spdlog::warn("UDP: the kernel refuses GSO messages ({}); sending each datagram on its own from now on",
                     std::strerror(err));
      }
    } else if (rejected_sends_++ % 1000 == 0) {
      spdlog::warn("UDP: cannot send {} bytes to {}:{}: {} ({} so far)", b.bytes, b.to.address().to_string(),
                   b.to.port(), std::strerror(err), rejected_sends_);
    }
    b.registration->in_flight -= b.count;
    ++batch_sent_;
  }
  clear_batch();
}

void UdpPublisher::clear_batch() {
  batch_.clear();
  batch_bytes_.clear();
  batch_sent_ = 0;
  if (batch_bytes_.capacity() > (std::size_t{4} << 20)) batch_bytes_.shrink_to_fit();  // after a burst
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
