#include "transport/calibrate.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <pthread.h>
#include <sched.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <limits>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace gmr::server {
namespace {

// A file descriptor closed when it goes.
class Fd {
 public:
  explicit Fd(int fd = -1) : fd_(fd) {}
  Fd(Fd&& o) noexcept : fd_(std::exchange(o.fd_, -1)) {}
  Fd& operator=(Fd&& o) noexcept {
    if (this != &o) {
      reset();
      fd_ = std::exchange(o.fd_, -1);
    }
    return *this;
  }
  ~Fd() { reset(); }
  int get() const { return fd_; }
  void reset() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  int fd_;
};

Error system_error(const std::string& what) {
  return make_error(ErrorKind::kIo, "send calibration: " + what + ": " + std::strerror(errno));
}

double thread_cpu_ns() {
  timespec t{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) * 1e9 + static_cast<double>(t.tv_nsec);
}

// Loopback TCP connections, each a writer (TCP_NODELAY) and a non-blocking
// reader, made by open().
class Loopback {
 public:
  Status open(std::size_t connections) {
    Fd listener(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
    if (listener.get() < 0) return system_error("socket");
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t length = sizeof address;
    if (::bind(listener.get(), reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
      return system_error("bind");
    }
    if (::listen(listener.get(), static_cast<int>(std::min<std::size_t>(connections, 4096))) != 0) {
      return system_error("listen");
    }
    if (::getsockname(listener.get(), reinterpret_cast<sockaddr*>(&address), &length) != 0) {
      return system_error("getsockname");
    }
    for (std::size_t k = 0; k < connections; ++k) {
      Fd writer(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
      if (writer.get() < 0) return system_error("socket");
      const int one = 1;
      ::setsockopt(writer.get(), IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
      if (::connect(writer.get(), reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
        return system_error("connect");
      }
      Fd reader(::accept4(listener.get(), nullptr, nullptr, SOCK_CLOEXEC | SOCK_NONBLOCK));
      if (reader.get() < 0) return system_error("accept");
      writers_.push_back(std::move(writer));
      readers_.push_back(std::move(reader));
    }
    return Ok{};
  }

  // The fastest of `passes` passes, in ns per send on the calling thread: a
  // pass writes one frame to each connection, as a stream's fan-out does,
  // timed by the thread's CPU clock; the readers are drained after it,
  // untimed. What a pass costs is the kernel's send path and the loopback
  // delivery it does in the sender's context; a pass that something else
  // interfered with only comes out slower.
  Result<double> fastest_pass(const std::string& frame, int passes) {
    back_.resize(4 * frame.size());
    double fastest = std::numeric_limits<double>::infinity();
    for (int p = 0; p < passes; ++p) {
      const double start = thread_cpu_ns();
      for (const Fd& writer : writers_) {
        for (std::size_t sent = 0; sent < frame.size();) {
          const ssize_t n = ::send(writer.get(), frame.data() + sent, frame.size() - sent, MSG_NOSIGNAL);
          if (n < 0 && errno == EINTR) continue;
          if (n <= 0) return system_error("send");
          sent += static_cast<std::size_t>(n);
        }
      }
      fastest = std::min(fastest, (thread_cpu_ns() - start) / static_cast<double>(writers_.size()));
      for (const Fd& reader : readers_) {
        while (::recv(reader.get(), back_.data(), back_.size(), 0) > 0) {
        }
      }
    }
    return std::max(1.0, fastest);
  }

 private:
  std::vector<Fd> writers_, readers_;
  std::vector<char> back_;
};

// Pins the calling thread to `cpu` (-1: leaves it where it is).
void pin(int cpu) {
  if (cpu < 0) return;
  cpu_set_t one;
  CPU_ZERO(&one);
  CPU_SET(cpu, &one);
  ::pthread_setaffinity_np(::pthread_self(), sizeof one, &one);
}

}  // namespace

Result<SendCalibration> calibrate_send_budget(std::size_t bytes, std::size_t connections, int passes, int rounds,
                                              std::chrono::milliseconds gap) {
  if (bytes == 0 || connections == 0 || passes <= 0 || rounds <= 0 || gap.count() < 0) {
    return make_error(ErrorKind::kInvalidArgument, "send calibration: needs bytes, connections, passes and rounds");
  }
  const auto began = std::chrono::steady_clock::now();
  // The CPUs this process may run on (at most 16 are measured).
  std::vector<int> cpus;
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (::sched_getaffinity(0, sizeof allowed, &allowed) == 0) {
    for (int c = 0; c < CPU_SETSIZE && cpus.size() < 16; ++c) {
      if (CPU_ISSET(c, &allowed)) cpus.push_back(c);
    }
  }
  if (cpus.empty()) cpus.push_back(-1);  // unknown: wherever the thread runs
  // One thread, pinned to each CPU in turn for a round of passes, then a
  // gap: a disturbance that lasts a while (the previous run's sockets
  // closing as the server starts) spares some rounds, and the whole takes
  // about `rounds` gaps however many CPUs there are.
  std::vector<double> fastest(cpus.size(), std::numeric_limits<double>::infinity());
  Status status = Ok{};
  std::thread t([&] {
    Loopback loopback;
    status = loopback.open(connections);
    if (!status) return;
    const std::string frame(bytes, 'f');
    const int per_round = (passes + rounds - 1) / rounds;  // so there are at most `rounds`
    for (int done = 0; done < passes; done += per_round) {
      if (done > 0) std::this_thread::sleep_for(gap);
      for (std::size_t c = 0; c < cpus.size(); ++c) {
        pin(cpus[c]);
        auto ns = loopback.fastest_pass(frame, std::min(per_round, passes - done));
        if (!ns.ok()) {
          status = ns.error();
          return;
        }
        fastest[c] = std::min(fastest[c], *ns);
      }
    }
  });
  t.join();
  if (!status) return status.error();
  SendCalibration out;
  out.ns_per_send = *std::max_element(fastest.begin(), fastest.end());
  out.fastest_ns_per_send = *std::min_element(fastest.begin(), fastest.end());
  out.cpus = cpus.size();
  out.budget = kReferenceBudget * kReferenceNsPerSend / out.fastest_ns_per_send;
  out.sends = connections * static_cast<std::size_t>(passes) * cpus.size();
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
  return out;
}

Result<double> measure_send_budget() {
  // Ten rounds of two passes (the first warms what a millisecond asleep
  // cooled), 1 ms apart: a running server's I/O threads wait at most two
  // passes (about 0.5 ms) for it. One pass a round measured 3-8% slow.
  auto c = calibrate_send_budget(kCalibrationBytes, kCalibrationConnections, 20, 10, std::chrono::milliseconds(1));
  if (!c.ok()) return c.error();
  return c->budget;
}

}  // namespace gmr::server
