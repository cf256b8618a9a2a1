// UdpSender: one I/O thread's UDP sending, for the UdpPublisher
// (udp_publisher.h), through its own descriptor of the publisher's socket.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/wire/udp.h"
#include "transport/io_threads.h"
#include "transport/net.h"

namespace gmr::server {

// Where one session's UDP frames go, once registered.
struct UdpRegistration {
  std::optional<udp::endpoint> endpoint;
  std::size_t lane = 0;  // the sender (I/O thread) its frames leave from
  // Guarded by that sender's lock:
  std::size_t in_flight = 0;          // datagrams batched, not yet handed to the kernel
  std::uint32_t next_message_id = 0;  // fragments of one message share an id
};

// One I/O thread's sending: a batch the control loop appends to (under m_)
// and the lane sends (sendmmsg), through its own descriptor of the socket.
//
//   control loop: send() --append--> filling_ --(lane takes it)--> sending_ --sendmmsg--> kernel
//
// flush_posted_ is true from the first append until the lane finds nothing
// left to send, so one flush at a time runs, and none is lost.
class UdpSender {
 public:
  // `threads` (may be null): where the lane's flushes are handed, batched.
  UdpSender(net::io_context& io, udp::socket& main, std::size_t max_in_flight, IoThreads* threads, std::size_t lane);

  // `head` then `body` to `to` as fragments; false, sending nothing, when `to`
  // is not registered or has max_in_flight datagrams in flight. `stamped`:
  // `head` is a frame's (frame_head_for), whose write stamp is filled in as
  // the message's first datagram leaves.
  bool send(const std::shared_ptr<UdpRegistration>& to, std::string_view head, std::string_view body, bool stamped);
  // No more sends; what waits is given back, and the lane closes its descriptor.
  void close();
  // How long the oldest datagram not yet handed to the kernel has waited
  // (zero: none waits). Read for every UDP subscriber of every tick: no lock,
  // and no clock when nothing waits.
  Clock::duration backlog() const;

  std::uint64_t send_calls() const { return send_calls_.load(std::memory_order_relaxed); }
  std::uint64_t datagrams_sent() const { return datagrams_sent_.load(std::memory_order_relaxed); }
  std::uint64_t bytes_sent() const { return bytes_sent_.load(std::memory_order_relaxed); }

 private:
  static constexpr std::size_t kNoStamp = static_cast<std::size_t>(-1);
  // Consecutive fragments of one frame to one address: one sendmmsg entry
  // (a GSO message when `count` > 1).
  struct Batched {
    std::size_t offset = 0;  // into Batch::bytes
    std::size_t bytes = 0;
    std::size_t count = 0;  // datagrams
    udp::endpoint to;
    std::shared_ptr<UdpRegistration> registration;
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
  static void release(Batch& b, std::size_t first);
  // On the lane: sends what was appended until nothing is left, or the
  // socket is full (it goes on when writable), or closed.
  void flush();
  // Hands sending_ from sent_ on to the kernel. False when the socket is
  // full: a wait for room is armed, which flushes again.
  bool send_some();

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

}  // namespace gmr::server
