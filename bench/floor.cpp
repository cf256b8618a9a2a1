// gmr-floor: the kernel's floor for what gmr-server sends. It sends the same
// number of frames of the same size to the same number of sockets, at the
// same rate, with nothing else to do: UDP with sendmmsg (one call per batch
// of up to 1,024 datagrams), TCP with one writev per connection and tick.
// A child process, pinned to another CPU, drains every socket (epoll), as
// gmr-load does. The sender's CPU per frame is what no server can beat on
// this machine; bench/server/run.sh divides gmr's by it (docs/performance.md,
// "The floor").
//
// By default every socket's frame of a tick leaves in one burst, as a shared
// stream sends. With --phases P the sockets are P groups, each sent at its own
// phase of the period (group g at k / rate + g / (P * rate)), as own streams
// that started at different times send: gmr-server's clock runs the ticks due
// within 0.5 ms of each other together, about 17 groups a period at 120 Hz.
// Fewer frames per burst mean more wake-ups of the receiver, which on
// loopback the sender pays for.
//
// TCP's writes can also go to the kernel as io_uring SENDMSG operations, one
// per connection and all of a tick's group in one submission (--tcp-send
// io_uring): one system call a burst instead of one a connection.
//
// Each frame carries the time its burst began (CLOCK_MONOTONIC, in its first
// 8 bytes); the receiver reports the latency of the measured window's frames
// (p50, p99, p99.9, max, from gmr-load's histogram, so they read as its do):
// how long the kernel alone makes the last of a burst wait, the bound a
// fan-out on this core cannot beat.
//
//   gmr-floor --transport udp|tcp --sockets N [--rate 120] [--bytes 510] [--phases 1] [--tcp-send writev|io_uring]
//             [--seconds 10] [--warmup 2] [--send-cpu 0] [--receive-cpu 1] [--json FILE]
//
// Prints one line; --json writes {"transport", "tcp_send", "sockets", "rate_hz", "bytes",
// "phases", "frames", "seconds", "cpu_seconds", "ns_per_frame", "late_ticks",
// "timed", "latency_ms": {"p50", "p99", "p99.9", "max"}}.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <sched.h>
#include <signal.h>
#include <sys/epoll.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "report.h"  // gmr-load's latency histogram
#ifdef GMR_HAVE_LIBURING
#include <liburing.h>
#endif

namespace {

using Clock = std::chrono::steady_clock;

[[noreturn]] void fail(const std::string& what) { throw std::runtime_error(what + ": " + std::strerror(errno)); }

void pin(int cpu) {
  if (cpu < 0) return;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  if (::sched_setaffinity(0, sizeof set, &set) != 0) fail("sched_setaffinity to CPU " + std::to_string(cpu));
}

double cpu_seconds() {
  rusage u{};
  ::getrusage(RUSAGE_SELF, &u);
  auto s = [](const timeval& t) { return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_usec) * 1e-6; };
  return s(u.ru_utime) + s(u.ru_stime);
}

sockaddr_in loopback(std::uint16_t port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(port);
  return a;
}

std::uint16_t bound_port(int fd) {
  sockaddr_in a{};
  socklen_t n = sizeof a;
  if (::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n) != 0) fail("getsockname");
  return ntohs(a.sin_port);
}

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
}

// Where a TCP receiver is in its stream of `bytes`-byte frames: the stamp
// may arrive cut between two reads.
struct StreamPlace {
  std::size_t pos = 0;  // bytes of the current frame read
  char stamp[8] = {};
};

// The receiving side: reads every socket until the parent closes `stop_fd`,
// timing the frames whose stamps are at or after the time the parent writes
// to `window_fd`; then writes the latencies' p50, p99, p99.9 and max (ns) and
// how many it timed to `result_fd`.
[[noreturn]] void drain(const std::vector<int>& fds, bool udp, std::size_t bytes, int stop_fd, int window_fd,
                        int result_fd, int cpu) {
  pin(cpu);
  const int ep = ::epoll_create1(0);
  for (int fd : fds) {
    epoll_event e{};
    e.events = EPOLLIN;
    e.data.fd = fd;
    ::epoll_ctl(ep, EPOLL_CTL_ADD, fd, &e);
  }
  for (const int fd : {stop_fd, window_fd}) {
    epoll_event e{};
    e.events = EPOLLIN;
    e.data.fd = fd;
    ::epoll_ctl(ep, EPOLL_CTL_ADD, fd, &e);
  }
  std::vector<epoll_event> ready(1024);
  std::vector<char> buf(1 << 16);
  std::vector<StreamPlace> place(static_cast<std::size_t>(*std::max_element(fds.begin(), fds.end())) + 1);
  gmr::load::Histogram latencies;
  std::int64_t window = std::numeric_limits<std::int64_t>::max();
  auto timed = [&](const char* stamp) {
    std::int64_t sent = 0;
    std::memcpy(&sent, stamp, sizeof sent);
    if (sent >= window) latencies.add(now_ns() - sent);
  };
  for (;;) {
    const int n = ::epoll_wait(ep, ready.data(), static_cast<int>(ready.size()), -1);
    for (int i = 0; i < n; ++i) {
      const int fd = ready[static_cast<std::size_t>(i)].data.fd;
      if (fd == window_fd) {
        if (::read(window_fd, &window, sizeof window) != sizeof window) window = 0;
        ::epoll_ctl(ep, EPOLL_CTL_DEL, window_fd, nullptr);
        continue;
      }
      if (fd == stop_fd) {
        const auto at = [&](double q) { return static_cast<std::int64_t>(latencies.quantile_ns(q)); };
        const std::int64_t out[5] = {at(0.5), at(0.99), at(0.999), latencies.max(),
                                     static_cast<std::int64_t>(latencies.count())};
        (void)!::write(result_fd, out, sizeof out);
        ::_exit(0);
      }
      for (;;) {
        const ssize_t got = ::recv(fd, buf.data(), buf.size(), MSG_DONTWAIT);
        if (got <= 0) break;
        if (udp) {  // a datagram, one frame
          if (static_cast<std::size_t>(got) >= sizeof(std::int64_t)) timed(buf.data());
          continue;
        }
        StreamPlace& at = place[static_cast<std::size_t>(fd)];
        for (std::size_t k = 0; k < static_cast<std::size_t>(got);) {
          if (at.pos < sizeof at.stamp) {
            at.stamp[at.pos++] = buf[k++];
            if (at.pos == sizeof at.stamp) timed(at.stamp);
          } else {
            const std::size_t skip = std::min(bytes - at.pos, static_cast<std::size_t>(got) - k);
            at.pos += skip;
            k += skip;
          }
          if (at.pos == bytes) at.pos = 0;
        }
      }
    }
  }
}

struct Result {
  std::uint64_t frames = 0, late_ticks = 0;
  double seconds = 0, cpu = 0;
};

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"gmr-floor: the kernel's cost of sending what gmr-server sends, with nothing else to do"};
  std::string transport = "udp", json;
  int sockets = 1000, send_cpu = 0, receive_cpu = 1, phases = 1;
  double rate = 120, seconds = 10, warmup = 2;
  std::size_t bytes = 510;  // a CMU 01_01 frame at float32 with its head, as gmr sends it
  app.add_option("--transport", transport, "udp (sendmmsg) or tcp (writev)")->check(CLI::IsMember({"udp", "tcp"}));
  app.add_option("--sockets", sockets, "Receiving sockets (subscribers)")->check(CLI::Range(1, 30000));
  app.add_option("--rate", rate, "Frames per second to each socket")->check(CLI::Range(1.0, 10000.0));
  app.add_option("--bytes", bytes, "Bytes per frame (a datagram, or a TCP message)")->check(CLI::Range(16, 65000));
  app.add_option("--phases", phases, "Groups of sockets sent at their own phase of the period (1: one burst)")
      ->check(CLI::Range(1, 1000));
  app.add_option("--seconds", seconds, "Measured window")->check(CLI::PositiveNumber);
  app.add_option("--warmup", warmup, "Seconds sent before the window")->check(CLI::NonNegativeNumber);
  app.add_option("--send-cpu", send_cpu, "CPU the sender is pinned to (-1: none)");
  app.add_option("--receive-cpu", receive_cpu, "CPU the receiver is pinned to (-1: none)");
  app.add_option("--json", json, "Also write the result as JSON");
  std::string tcp_send = "writev";
  app.add_option("--tcp-send", tcp_send,
                 "TCP: one writev per connection, or io_uring (a tick's group in one submission)")
      ->check(CLI::IsMember({"writev", "io_uring"}));
  CLI11_PARSE(app, argc, argv);

  try {
    const bool udp = transport == "udp";
    rlimit lim{};
    ::getrlimit(RLIMIT_NOFILE, &lim);
    lim.rlim_cur = lim.rlim_max;
    ::setrlimit(RLIMIT_NOFILE, &lim);
    // Both ends, made before the fork; each side closes the other's.
    std::vector<int> send_fds, receive_fds;
    std::vector<sockaddr_in> to;
    int udp_sender = -1;
    if (udp) {
      udp_sender = ::socket(AF_INET, SOCK_DGRAM, 0);
      if (udp_sender < 0) fail("socket");
      const int sndbuf = 8 << 20;
      ::setsockopt(udp_sender, SOL_SOCKET, SO_SNDBUF, &sndbuf, sizeof sndbuf);
      for (int i = 0; i < sockets; ++i) {
        const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
        if (fd < 0) fail("socket " + std::to_string(i));
        const auto a = loopback(0);
        if (::bind(fd, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) fail("bind");
        receive_fds.push_back(fd);
        to.push_back(loopback(bound_port(fd)));
      }
    } else {
      const int listener = ::socket(AF_INET, SOCK_STREAM, 0);
      const auto a = loopback(0);
      if (listener < 0 || ::bind(listener, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0 ||
          ::listen(listener, 4096) != 0) {
        fail("listen");
      }
      const auto at = loopback(bound_port(listener));
      const int one = 1;
      for (int i = 0; i < sockets; ++i) {
        const int w = ::socket(AF_INET, SOCK_STREAM, 0);
        if (w < 0 || ::connect(w, reinterpret_cast<const sockaddr*>(&at), sizeof at) != 0) fail("connect");
        ::setsockopt(w, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
        const int r = ::accept(listener, nullptr, nullptr);
        if (r < 0) fail("accept");
        send_fds.push_back(w);
        receive_fds.push_back(r);
      }
      ::close(listener);
    }
    int stop[2], window[2], result[2];
    if (::pipe(stop) != 0 || ::pipe(window) != 0 || ::pipe(result) != 0) fail("pipe");
    const pid_t child = ::fork();
    if (child < 0) fail("fork");
    if (child == 0) {
      ::close(stop[1]);
      ::close(window[1]);
      ::close(result[0]);
      for (int fd : send_fds) ::close(fd);
      drain(receive_fds, udp, bytes, stop[0], window[0], result[1], receive_cpu);
    }
    ::close(stop[0]);
    ::close(window[0]);
    ::close(result[1]);
    for (int fd : receive_fds) ::close(fd);
    pin(send_cpu);

    // gmr's frame: a small head (ids, stamp) and the shared body, as two
    // pieces, the way the server hands them to the kernel.
    // The head's first 8 bytes: the time its burst began.
    std::string head(std::min<std::size_t>(24, bytes / 2), 'h');
    const std::string body(bytes - head.size(), 'b');
    constexpr std::size_t kBatch = 1024;
    std::vector<mmsghdr> msgs(kBatch);
    std::vector<iovec> iovs(2 * kBatch);
    const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate));
    Result r;
    // Group g is sockets [g * N / P, (g + 1) * N / P).
    const auto group = [&](int g, std::size_t count) {
      return std::pair<std::size_t, std::size_t>(
          count * static_cast<std::size_t>(g) / static_cast<std::size_t>(phases),
          count * static_cast<std::size_t>(g + 1) / static_cast<std::size_t>(phases));
    };
    const bool uring = !udp && tcp_send == "io_uring";
    std::function<void(std::pair<std::size_t, std::size_t>)> send_uring;
#ifdef GMR_HAVE_LIBURING
    io_uring ring{};
    std::vector<msghdr> hdrs(send_fds.size());
    if (uring) {
      if (const int e =
              io_uring_queue_init(static_cast<unsigned>(std::min<std::size_t>(send_fds.size(), 4096)), &ring, 0);
          e < 0) {
        errno = -e;
        fail("io_uring_queue_init");
      }
      const unsigned depth = std::min<unsigned>(static_cast<unsigned>(send_fds.size()), 4096);
      send_uring = [&, depth](std::pair<std::size_t, std::size_t> range) {
        for (std::size_t first = range.first; first < range.second; first += depth) {
          const std::size_t n = std::min<std::size_t>(depth, range.second - first);
          for (std::size_t i = first; i < first + n; ++i) {
            iovs[0] = {const_cast<char*>(head.data()), head.size()};
            iovs[1] = {const_cast<char*>(body.data()), body.size()};
            hdrs[i] = {};
            hdrs[i].msg_iov = iovs.data();
            hdrs[i].msg_iovlen = 2;
            io_uring_prep_sendmsg(io_uring_get_sqe(&ring), send_fds[i], &hdrs[i], MSG_DONTWAIT);
          }
          io_uring_submit_and_wait(&ring, static_cast<unsigned>(n));
          io_uring_cqe* cqe = nullptr;
          unsigned at = 0, seen = 0;
          io_uring_for_each_cqe(&ring, at, cqe) {
            if (cqe->res == static_cast<int>(bytes)) ++r.frames;
            ++seen;
          }
          io_uring_cq_advance(&ring, seen);
        }
      };
    }
#else
    if (uring) throw std::runtime_error("built without liburing-dev: no --tcp-send io_uring");
#endif
    auto tick = [&](int g) {
      const std::int64_t stamp = now_ns();
      std::memcpy(head.data(), &stamp, sizeof stamp);
      if (udp) {
        const auto [begin, end] = group(g, to.size());
        for (std::size_t first = begin; first < end; first += kBatch) {
          const std::size_t n = std::min(kBatch, end - first);
          for (std::size_t i = 0; i < n; ++i) {
            iovs[2 * i] = {const_cast<char*>(head.data()), head.size()};
            iovs[2 * i + 1] = {const_cast<char*>(body.data()), body.size()};
            msgs[i] = {};
            msgs[i].msg_hdr.msg_name = &to[first + i];
            msgs[i].msg_hdr.msg_namelen = sizeof(sockaddr_in);
            msgs[i].msg_hdr.msg_iov = &iovs[2 * i];
            msgs[i].msg_hdr.msg_iovlen = 2;
          }
          for (std::size_t done = 0; done < n;) {
            const int k = ::sendmmsg(udp_sender, msgs.data() + done, static_cast<unsigned>(n - done), 0);
            if (k < 0 && errno == EINTR) continue;
            if (k <= 0) break;  // the socket buffer is full: the rest of this tick is dropped, as gmr drops
            done += static_cast<std::size_t>(k);
            r.frames += static_cast<std::uint64_t>(k);
          }
        }
      } else if (uring) {
        send_uring(group(g, send_fds.size()));
      } else {
        iovec v[2] = {{const_cast<char*>(head.data()), head.size()}, {const_cast<char*>(body.data()), body.size()}};
        const auto [begin, end] = group(g, send_fds.size());
        for (std::size_t i = begin; i < end; ++i) {
          if (::writev(send_fds[i], v, 2) == static_cast<ssize_t>(bytes)) ++r.frames;
        }
      }
    };
    // Every frame is due at start + k / rate (+ its group's phase), as gmr's streams are.
    auto run = [&](double s, bool measured) {
      const auto start = Clock::now();
      const auto end = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
      for (std::uint64_t k = 0;; ++k) {
        for (int g = 0; g < phases; ++g) {
          const auto due = start + k * period + g * period / phases;
          if (due >= end) return;
          const auto now = Clock::now();
          if (now < due) {
            std::this_thread::sleep_until(due);
          } else if (measured && now - due > period) {
            ++r.late_ticks;
          }
          tick(g);
        }
      }
    };
    run(warmup, false);
    r = Result{};
    const double cpu0 = cpu_seconds();
    const auto t0 = Clock::now();
    const std::int64_t from = now_ns();
    if (::write(window[1], &from, sizeof from) != sizeof from) fail("write to the receiver");
    run(seconds, true);
    r.cpu = cpu_seconds() - cpu0;
    r.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    ::close(stop[1]);
    std::int64_t latency[5] = {};  // p50, p99, p99.9, max (ns), frames timed
    for (std::size_t got = 0; got < sizeof latency;) {
      const ssize_t k = ::read(result[0], reinterpret_cast<char*>(latency) + got, sizeof latency - got);
      if (k <= 0) fail("read the receiver's latencies");
      got += static_cast<std::size_t>(k);
    }
    ::waitpid(child, nullptr, 0);
    const auto ms = [&](int i) { return static_cast<double>(latency[i]) / 1e6; };

    const double ns = r.frames > 0 ? 1e9 * r.cpu / static_cast<double>(r.frames) : 0.0;
    std::printf(
        "gmr-floor: %s%s to %d sockets, %.0f Hz, %zu bytes, %d phase%s: %llu frames in %.2f s, %.3f cores, %.0f ns "
        "per frame, %llu late ticks; %lld timed, latency p50 %.3f ms p99 %.3f ms p99.9 %.3f ms max %.3f ms\n",
        transport.c_str(), uring ? " (io_uring)" : "", sockets, rate, bytes, phases, phases == 1 ? "" : "s",
        static_cast<unsigned long long>(r.frames), r.seconds, r.cpu / r.seconds, ns,
        static_cast<unsigned long long>(r.late_ticks), static_cast<long long>(latency[4]), ms(0), ms(1), ms(2), ms(3));
    if (!json.empty()) {
      std::ofstream out(json + ".partial");
      out << "{\"transport\": \"" << transport << "\", \"tcp_send\": \"" << (udp ? "" : tcp_send.c_str())
          << "\", \"sockets\": " << sockets << ", \"rate_hz\": " << rate << ", \"bytes\": " << bytes
          << ", \"phases\": " << phases << ", \"frames\": " << r.frames << ", \"seconds\": " << r.seconds
          << ", \"cpu_seconds\": " << r.cpu << ", \"ns_per_frame\": " << ns << ", \"late_ticks\": " << r.late_ticks
          << ", \"timed\": " << latency[4] << ", \"latency_ms\": {\"p50\": " << ms(0) << ", \"p99\": " << ms(1)
          << ", \"p99.9\": " << ms(2) << ", \"max\": " << ms(3) << "}"
          << "}\n";
      out.close();
      if (!out || std::rename((json + ".partial").c_str(), json.c_str()) != 0) fail("cannot write " + json);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gmr-floor: %s\n", e.what());
    return 1;
  }
  return 0;
}
