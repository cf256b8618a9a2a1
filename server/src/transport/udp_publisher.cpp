#include "transport/udp_publisher.h"

#include <spdlog/spdlog.h>

#include <netinet/udp.h>
#include <sys/random.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <limits>
#include <array>
#include <atomic>
#include <cerrno>
#include <cstring>
#include <mutex>
#include <stdexcept>
#include <string>

#include "gmr/wire/frames.h"
#include "gmr/wire/udp.h"

namespace gmr::server {

#ifndef UDP_SEGMENT
#define UDP_SEGMENT 103  // linux/udp.h, for C libraries that predate it
#endif

namespace {

// UDP GSO limits: at most 64 segments, and the whole message within one
// IP datagram's 64 KiB.
constexpr std::size_t kMaxGsoSegments = std::min<std::size_t>(64, 65000 / wire::kMaxDatagramBytes);
constexpr std::size_t kNoStamp = static_cast<std::size_t>(-1);
// Entries per sendmmsg call (the kernel caps a call at UIO_MAXIOV, 1024).
constexpr std::size_t kSendBatch = 256;
// Datagrams read per pass of the event loop.
constexpr int kReceiveBatch = 64;

}  // namespace

// One I/O thread's sending: a batch the control loop appends to (under m_)
// and the lane sends (sendmmsg), through its own descriptor of the socket.
//
//   control loop: send() --append--> filling_ --(lane takes it)--> sending_ --sendmmsg--> kernel
//
// flush_posted_ is true from the first append until the lane finds nothing
// left to send, so one flush at a time runs, and none is lost.
class UdpPublisher::Sender {
 public:
  // `threads` (may be null): where the lane's flushes are handed, batched.
  Sender(net::io_context& io, udp::socket& main, std::size_t max_in_flight, IoThreads* threads, std::size_t lane)
      : socket_(io), max_in_flight_(max_in_flight), threads_(threads), lane_(lane) {
    const int fd = ::dup(main.native_handle());
    if (fd < 0) throw std::runtime_error(std::string("cannot duplicate the UDP socket: ") + std::strerror(errno));
    boost::system::error_code ec;
    socket_.assign(main.local_endpoint().protocol(), fd, ec);
    if (ec) {
      ::close(fd);
      throw std::runtime_error("cannot use the UDP socket on an I/O thread: " + ec.message());
    }
  }

  // `stamped`: `head` is a frame's (frame_head_for), whose write stamp is
  // filled in as the message's first datagram leaves.
  bool send(const std::shared_ptr<Registration>& to, std::string_view head, std::string_view body, bool stamped) {
    std::lock_guard lock(m_);
    if (closed_ || !to->endpoint) return false;
    if (to->in_flight + wire::fragment_count(head.size() + body.size()) > max_in_flight_) return false;
    if (filling_.entries.empty()) {
      filling_since_ = Clock::now();
      if (!sending_active_) oldest_.store(filling_since_.time_since_epoch().count(), std::memory_order_relaxed);
    }
    std::size_t at = filling_.bytes.size();
    const std::size_t appended = wire::append_fragments(filling_.bytes, to->next_message_id++, head, body);
    const std::size_t end = filling_.bytes.size();
    // Without GSO every datagram is its own entry; with it, runs of up to
    // kMaxGsoSegments share one.
    const std::size_t per_entry = gso_.load(std::memory_order_relaxed) ? kMaxGsoSegments : 1;
    const std::size_t first = filling_.entries.size();
    for (std::size_t done = 0; done < appended;) {
      const std::size_t n = std::min(per_entry, appended - done);
      const std::size_t bytes = std::min(n * wire::kMaxDatagramBytes, end - at);
      filling_.entries.push_back(Batched{at, bytes, n, *to->endpoint, to});
      at += bytes;
      done += n;
    }
    // The stamp ends the head, which is far shorter than a fragment: it is
    // in the first datagram, after its header.
    static_assert(wire::kMaxFragmentPayload > 64);
    if (stamped && head.size() >= wire::kWriteStampBytes && head.size() <= wire::kMaxFragmentPayload) {
      filling_.entries[first].stamp_at = filling_.entries[first].offset + wire::kFragmentHeaderBytes + head.size() - 8;
    }
    to->in_flight += appended;
    if (!flush_posted_) {
      flush_posted_ = true;
      // After the control loop's pass: its whole fan-out in one batch.
      if (threads_ != nullptr) {
        threads_->defer(lane_, LaneTask{[](void* s) { static_cast<Sender*>(s)->flush(); }, this, nullptr});
      } else {
        net::post(socket_.get_executor(), [this] { flush(); });
      }
    }
    return true;
  }

  // No more sends; what waits is given back, and the lane closes its descriptor.
  void close() {
    {
      std::lock_guard lock(m_);
      closed_ = true;
    }
    net::post(socket_.get_executor(), [this] {
      boost::system::error_code ec;
      socket_.close(ec);
      flush();  // gives back what waits (a flush waiting for room ends with operation_aborted)
    });
  }

  // How long the oldest datagram not yet handed to the kernel has waited
  // (zero: none waits). Read for every UDP subscriber of every tick: no lock,
  // and no clock when nothing waits.
  Clock::duration backlog() const {
    const Clock::rep since = oldest_.load(std::memory_order_relaxed);
    if (since == kNoneWaits) return Clock::duration::zero();
    return std::max(Clock::duration::zero(), Clock::now() - Clock::time_point(Clock::duration(since)));
  }

  std::uint64_t send_calls() const { return send_calls_.load(std::memory_order_relaxed); }
  std::uint64_t datagrams_sent() const { return datagrams_sent_.load(std::memory_order_relaxed); }
  std::uint64_t bytes_sent() const { return bytes_sent_.load(std::memory_order_relaxed); }

 private:
  // Consecutive fragments of one frame to one address: one sendmmsg entry
  // (a GSO message when `count` > 1).
  struct Batched {
    std::size_t offset = 0;  // into Batch::bytes
    std::size_t bytes = 0;
    std::size_t count = 0;   // datagrams
    udp::endpoint to;
    std::shared_ptr<Registration> registration;
    // On a frame's first entry: where in the batch its write stamp's 8
    // value bytes are (kNoStamp: none).
    std::size_t stamp_at = kNoStamp;
  };
  struct Batch {
    std::string bytes;
    std::vector<Batched> entries;
    void clear() {
      entries.clear();
      bytes.clear();
      if (bytes.capacity() > (std::size_t{4} << 20)) bytes.shrink_to_fit();  // after a burst
    }
  };

  // Gives entries [first, end) of `b` back to their registrations, unsent (m_ held).
  static void release(Batch& b, std::size_t first) {
    for (std::size_t i = first; i < b.entries.size(); ++i) b.entries[i].registration->in_flight -= b.entries[i].count;
  }

  // On the lane: sends what was appended until nothing is left, or the
  // socket is full (it goes on when writable), or closed.
  void flush() {
    for (;;) {
      {
        std::lock_guard lock(m_);
        if (closed_) {
          release(sending_, sent_);
          release(filling_, 0);
          sending_.clear();
          filling_.clear();
          sent_ = 0;
          oldest_.store(kNoneWaits, std::memory_order_relaxed);
          return;
        }
        if (sent_ == sending_.entries.size()) {
          sending_.clear();
          sent_ = 0;
          sending_active_ = false;
          if (filling_.entries.empty()) {
            flush_posted_ = false;
            oldest_.store(kNoneWaits, std::memory_order_relaxed);
            return;
          }
          std::swap(filling_, sending_);
          sending_active_ = true;
          oldest_.store(filling_since_.time_since_epoch().count(), std::memory_order_relaxed);
        }
      }
      if (!send_some()) return;
    }
  }

  // Hands sending_ from sent_ on to the kernel. False when the socket is
  // full: a wait for room is armed, which flushes again.
  bool send_some() {
    std::array<mmsghdr, kSendBatch> msgs;
    std::array<iovec, kSendBatch> iovs;
    alignas(cmsghdr) std::array<char, kSendBatch * CMSG_SPACE(sizeof(std::uint16_t))> controls;
    const int fd = socket_.native_handle();
    while (sent_ < sending_.entries.size()) {
      const std::size_t n = std::min(kSendBatch, sending_.entries.size() - sent_);
      // The frames this call starts are stamped with its time (a frame's
      // later fragments have not left yet).
      const std::int64_t now = now_ns();
      for (std::size_t i = 0; i < n; ++i) {
        const Batched& b = sending_.entries[sent_ + i];
        if (b.stamp_at != kNoStamp) wire::set_write_stamp(sending_.bytes.data() + b.stamp_at, now);
      }
      for (std::size_t i = 0; i < n; ++i) {
        Batched& b = sending_.entries[sent_ + i];
        iovs[i] = iovec{sending_.bytes.data() + b.offset, b.bytes};
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
      send_calls_.fetch_add(1, std::memory_order_relaxed);
      if (sent > 0) {
        std::size_t datagrams = 0, bytes = 0;
        {
          std::lock_guard lock(m_);
          for (int i = 0; i < sent; ++i) {
            Batched& b = sending_.entries[sent_ + static_cast<std::size_t>(i)];
            b.registration->in_flight -= b.count;
            datagrams += b.count;
            bytes += b.bytes;
          }
        }
        datagrams_sent_.fetch_add(datagrams, std::memory_order_relaxed);
        bytes_sent_.fetch_add(bytes, std::memory_order_relaxed);
        sent_ += static_cast<std::size_t>(sent);
        continue;
      }
      const int err = sent < 0 ? errno : EAGAIN;
      if (err == EINTR) continue;
      if (err == EAGAIN || err == EWOULDBLOCK || err == ENOBUFS) {
        // The socket buffer is full: the rest goes when the kernel has room.
        socket_.async_wait(udp::socket::wait_write, [this](const boost::system::error_code& ec) {
          if (ec == net::error::operation_aborted) {
            std::lock_guard lock(m_);
            closed_ = true;
          }
          flush();
        });
        return false;
      }
      // The first entry failed on its own (an address the kernel will not
      // send to, or a GSO message the device cannot segment): it is lost, as
      // any datagram may be, and the rest still go.
      Batched& b = sending_.entries[sent_];
      if (b.count > 1 && (err == EIO || err == EINVAL || err == ENOPROTOOPT)) {
        if (gso_.exchange(false)) {
          spdlog::warn("UDP: the kernel refuses GSO messages ({}); sending each datagram on its own from now on",
                       std::strerror(err));
        }
      } else if (rejected_sends_++ % 1000 == 0) {
        spdlog::warn("UDP: cannot send {} bytes to {}:{}: {} ({} so far)", b.bytes, b.to.address().to_string(),
                     b.to.port(), std::strerror(err), rejected_sends_);
      }
      {
        std::lock_guard lock(m_);
        b.registration->in_flight -= b.count;
      }
      ++sent_;
    }
    return true;
  }

  std::mutex m_;
  udp::socket socket_;
  std::size_t max_in_flight_;
  IoThreads* threads_;
  std::size_t lane_;
  // Guarded by m_:
  Batch filling_;
  Clock::time_point filling_since_{};  // its first entry's
  bool sending_active_ = false;        // sending_ holds entries the lane is sending
  // When the oldest entry not yet sent was batched (sending_'s first when
  // the lane is sending, else filling_'s), as Clock ticks; kNoneWaits when
  // none waits. Written under m_, read by backlog() without it.
  static constexpr Clock::rep kNoneWaits = std::numeric_limits<Clock::rep>::min();
  std::atomic<Clock::rep> oldest_{kNoneWaits};
  bool flush_posted_ = false;
  bool closed_ = false;
  // The lane's alone:
  Batch sending_;
  std::size_t sent_ = 0;  // entries of sending_ handed to the kernel
  std::uint64_t rejected_sends_ = 0;
  std::atomic<bool> gso_{true};  // until the kernel refuses a GSO message
  std::atomic<std::uint64_t> send_calls_{0};
  std::atomic<std::uint64_t> datagrams_sent_{0};
  std::atomic<std::uint64_t> bytes_sent_{0};  // UDP payload bytes
};

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
    senders_.push_back(std::make_unique<Sender>(static_cast<net::io_context&>(socket_.get_executor().context()),
                                                socket_, max_in_flight_, nullptr, 0));
    return;
  }
  for (std::size_t lane = 0; lane < threads->size(); ++lane) {
    senders_.push_back(std::make_unique<Sender>(threads->io(lane), socket_, max_in_flight_, threads, lane));
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
