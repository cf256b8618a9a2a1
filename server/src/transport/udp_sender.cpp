#include "transport/udp_sender.h"

#include <spdlog/spdlog.h>

#include <netinet/udp.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>

#include "gmr/wire/frames.h"

namespace gmr::server {

#ifndef UDP_SEGMENT
#define UDP_SEGMENT 103  // linux/udp.h, for C libraries that predate it
#endif

namespace {

// UDP GSO limits: at most 64 segments, and the whole message within one
// IP datagram's 64 KiB.
constexpr std::size_t kMaxGsoSegments = std::min<std::size_t>(64, 65000 / wire::kMaxDatagramBytes);
// Entries per sendmmsg call (the kernel caps a call at UIO_MAXIOV, 1024).
constexpr std::size_t kSendBatch = 256;

}  // namespace

UdpSender::UdpSender(net::io_context& io, udp::socket& main, std::size_t max_in_flight, IoThreads* threads,
                     std::size_t lane)
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

bool UdpSender::send(const std::shared_ptr<UdpRegistration>& to, std::string_view head, std::string_view body,
                     bool stamped) {
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
      threads_->defer(lane_, LaneTask{[](void* s) { static_cast<UdpSender*>(s)->flush(); }, this, nullptr});
    } else {
      net::post(socket_.get_executor(), [this] { flush(); });
    }
  }
  return true;
}

void UdpSender::close() {
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

Clock::duration UdpSender::backlog() const {
  const Clock::rep since = oldest_.load(std::memory_order_relaxed);
  if (since == kNoneWaits) return Clock::duration::zero();
  return std::max(Clock::duration::zero(), Clock::now() - Clock::time_point(Clock::duration(since)));
}

void UdpSender::release(Batch& b, std::size_t first) {
  for (std::size_t i = first; i < b.entries.size(); ++i) b.entries[i].registration->in_flight -= b.entries[i].count;
}

void UdpSender::flush() {
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

bool UdpSender::send_some() {
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

}  // namespace gmr::server
