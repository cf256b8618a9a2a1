#include "transport/io_threads.h"

#include <unistd.h>

#include <pthread.h>
#include <sched.h>

#include <algorithm>
#include <exception>
#include <string>

#include <spdlog/spdlog.h>

namespace gmr::server {

std::size_t io_thread_count(std::size_t configured) {
  if (configured != 0) return std::min(configured, kMaxIoThreads);
  cpu_set_t set;
  CPU_ZERO(&set);
  std::size_t cpus = 0;
  if (::sched_getaffinity(0, sizeof set, &set) == 0) cpus = static_cast<std::size_t>(CPU_COUNT(&set));
  if (cpus == 0) cpus = std::max(1u, std::thread::hardware_concurrency());
  return std::min(cpus, kMaxIoThreads);
}

IoThreads::IoThreads(net::io_context& control, std::size_t count) {
  count = std::max<std::size_t>(1, count);
  for (std::size_t i = 0; i < count; ++i) {
    auto lane = std::make_unique<Lane>();
    if (i == 0) {
      lane->io = &control;
    } else {
      // One thread runs it: Asio may then skip the locking a shared loop needs.
      lane->own = std::make_unique<net::io_context>(1);
      lane->io = lane->own.get();
      lane->guard.emplace(lane->own->get_executor());
    }
    lanes_.push_back(std::move(lane));
  }
}

IoThreads::~IoThreads() {
  // A server that never ran its control loop (start() threw) still joins.
  for (auto& lane : lanes_) {
    if (lane->own) lane->own->stop();
  }
  join();
}

std::size_t IoThreads::assign() {
  // From three lanes on, the control loop keeps its thread for what only it
  // does (ticks, kinematics, fan-out to every lane); with two, it shares the
  // sending, which is most of the work.
  const std::size_t first = lanes_.size() >= kControlAloneFrom ? 1 : 0;
  std::size_t best = first;
  for (std::size_t i = first + 1; i < lanes_.size(); ++i) {
    if (lanes_[i]->connections < lanes_[best]->connections) best = i;
  }
  ++lanes_[best]->connections;
  return best;
}

void IoThreads::release(std::size_t lane) {
  if (lane < lanes_.size() && lanes_[lane]->connections > 0) --lanes_[lane]->connections;
}

void IoThreads::defer(std::size_t lane, LaneTask task) {
  lanes_[lane]->deferred.push_back(std::move(task));
  if (hand_off_posted_) return;
  hand_off_posted_ = true;
  // Behind the handlers already queued: the rest of this pass adds to the batch.
  net::post(*lanes_[0]->io, [this] { hand_off(); });
}

void IoThreads::hand_off() {
  hand_off_posted_ = false;
  for (auto& lane : lanes_) {
    if (lane->deferred.empty()) continue;
    std::vector<LaneTask> batch;
    batch.swap(lane->deferred);
    if (lane->own == nullptr) {  // lane 0: this thread
      for (auto& t : batch) t.run(t.arg);
      continue;
    }
    net::post(*lane->io, [batch = std::move(batch)] {
      for (const auto& t : batch) t.run(t.arg);
    });
  }
}

void IoThreads::start() {
  for (std::size_t i = 1; i < lanes_.size(); ++i) {
    Lane& lane = *lanes_[i];
    if (lane.thread.joinable()) continue;
    lane.thread = std::thread([&lane, i] {
      // "gmr-io-3" in top -H, perf and /proc/PID/task/*/comm.
      const std::string name = "gmr-io-" + std::to_string(i);
      ::pthread_setname_np(::pthread_self(), name.c_str());
      try {
        lane.io->run();
      } catch (const std::exception& e) {
        spdlog::critical("I/O thread {} stopped: {}", i, e.what());
      }
    });
  }
}

void IoThreads::join() {
  for (auto& lane : lanes_) {
    lane->guard.reset();  // out of work once its connections have closed
    if (lane->thread.joinable()) lane->thread.join();
  }
}

tcp::socket IoThreads::adopt(tcp::socket socket, std::size_t lane, boost::system::error_code& ec) {
  const auto protocol = socket.local_endpoint(ec).protocol();
  tcp::socket moved(io(lane));
  if (!ec) {
    const auto fd = socket.release(ec);
    if (!ec) {
      moved.assign(protocol, fd, ec);
      if (ec) ::close(fd);
    }
  }
  return moved;
}

}  // namespace gmr::server
