// IoThreads: the server's I/O threads. Lane 0 is the control loop (the
// io_context the caller runs): the listener, requests and views, streams,
// HTTP, live sources. Lanes 1..N-1 each run an io_context of their own on a
// thread of their own and carry only socket I/O: accepted TCP connections
// are spread over the lanes (the one with the fewest first; with three or
// more lanes not over lane 0, which keeps its core for the control loop),
// and each connection's reads, writes and watchdog, and the UDP sends of its
// subscriptions, run on its lane.
//
//        control loop (lane 0)                       lane k
//   requests, views, streams: FK + one   --frames-->  Connection: write, read
//   encoding per tick, fan-out            <--bodies--  (requests go to lane 0)
//                                         --datagrams-> UDP sender: sendmmsg
//
// So the kernel's per-frame work (one send per subscriber per frame, most
// of a busy server's time) runs on every core, while each frame is still
// computed and encoded once. With one lane everything runs on one thread.
//
// Hand-offs are batched: what the control loop gives a lane during one pass
// of its event loop (say a tick's fan-out to a thousand subscribers) reaches
// the lane as one posted batch, one wake-up of its thread, not one per frame.
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <thread>
#include <vector>

#include "transport/net.h"

namespace gmr::server {

// The I/O threads `configured` asks for: itself, or with 0 one per CPU this
// process may run on (sched_getaffinity), at most kMaxIoThreads.
inline constexpr std::size_t kMaxIoThreads = 64;
std::size_t io_thread_count(std::size_t configured);

// Work for a lane: `run(arg)`, with `keep` holding what arg points into
// alive until it ran. No allocation per task.
struct LaneTask {
  void (*run)(void* arg) = nullptr;
  void* arg = nullptr;
  std::shared_ptr<void> keep;
};

class IoThreads {
 public:
  // `control` is lane 0, run by its owner; `count` lanes in all (at least 1).
  IoThreads(net::io_context& control, std::size_t count);
  ~IoThreads();
  IoThreads(const IoThreads&) = delete;
  IoThreads& operator=(const IoThreads&) = delete;

  std::size_t size() const { return lanes_.size(); }
  net::io_context& io(std::size_t lane) { return *lanes_[lane]->io; }
  // Control loop only: the lane a new connection goes to (the fewest
  // connections; the lowest index on a tie), counted there until release().
  // From kControlAloneFrom lanes on, never lane 0.
  static constexpr std::size_t kControlAloneFrom = 3;
  std::size_t assign();
  void release(std::size_t lane);
  // `socket`'s descriptor moved to lane `lane`'s io_context: its reads,
  // writes and timers run on that thread from then on. On failure `ec` says
  // why (the descriptor is closed).
  tcp::socket adopt(tcp::socket socket, std::size_t lane, boost::system::error_code& ec);
  std::size_t connections(std::size_t lane) const { return lanes_[lane]->connections; }

  // Control loop only: runs `task` on `lane` once the control loop's current
  // pass is done (on lane 0 itself then), in the order given. All the tasks
  // a pass gives one lane go to it in one post.
  void defer(std::size_t lane, LaneTask task);

  // Starts the threads of lanes 1..N-1 (they run until join()).
  void start();
  // After the control loop has ended: lets lanes 1..N-1 finish what they
  // still have (connections closing) and joins them. Idempotent.
  void join();

 private:
  struct Lane {
    net::io_context* io = nullptr;
    std::unique_ptr<net::io_context> own;  // lanes 1..N-1
    std::optional<net::executor_work_guard<net::io_context::executor_type>> guard;
    std::thread thread;
    std::size_t connections = 0;
    std::vector<LaneTask> deferred;  // control loop's: for this lane, this pass
  };
  // On the control loop, after a pass: each lane's deferred tasks to it.
  void hand_off();

  std::vector<std::unique_ptr<Lane>> lanes_;
  bool hand_off_posted_ = false;
};

}  // namespace gmr::server
