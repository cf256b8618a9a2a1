// What one UDP datagram costs the sending thread, by the way it is handed to
// the kernel: one sendto(2) each, sendmmsg(2) batches (what the server's UDP
// senders do), or io_uring SENDMSG operations submitted in batches of the
// same size (docs/performance.md, "io_uring"). Each datagram goes to another
// of 256 loopback sockets, as a fan-out's go to other subscribers; the
// receivers never read, so after their buffers fill the kernel drops at
// their queue: every method pays the same delivery work, which on loopback
// the sender's thread does.
//
//   build/bin/gmr_udp_send_bench --benchmark_repetitions=3
#include <arpa/inet.h>
#include <liburing.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <benchmark/benchmark.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

constexpr std::size_t kReceivers = 256;
constexpr std::size_t kDatagramBytes = 600;  // a float32 frame of 38 joints, with its headers

int udp_socket() {
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK, 0);
  if (fd < 0) throw std::runtime_error(std::string("socket: ") + std::strerror(errno));
  return fd;
}

sockaddr_in loopback(std::uint16_t port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  return a;
}

// 256 bound receivers with small buffers, and one sender.
struct Fixture {
  std::vector<int> receivers;
  std::vector<sockaddr_in> to;
  int sender = -1;
  std::string payload = std::string(kDatagramBytes, 'g');

  Fixture() {
    for (std::size_t i = 0; i < kReceivers; ++i) {
      const int fd = udp_socket();
      const int small = 4096;
      ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
      sockaddr_in a = loopback(0);
      if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) throw std::runtime_error("bind");
      socklen_t len = sizeof a;
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
      receivers.push_back(fd);
      to.push_back(a);
    }
    sender = udp_socket();
    const int big = 4 << 20;
    ::setsockopt(sender, SOL_SOCKET, SO_SNDBUF, &big, sizeof big);
  }
  ~Fixture() {
    for (int fd : receivers) ::close(fd);
    ::close(sender);
  }
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

// One datagram of the payload to receiver `to`, described in `h` and `iov`.
void describe(const Fixture& f, const sockaddr_in& to, msghdr& h, iovec& iov) {
  iov = iovec{const_cast<char*>(f.payload.data()), f.payload.size()};
  h = msghdr{};
  h.msg_name = const_cast<sockaddr_in*>(&to);
  h.msg_namelen = sizeof to;
  h.msg_iov = &iov;
  h.msg_iovlen = 1;
}

void count(benchmark::State& state, std::size_t sent, std::size_t failed) {
  state.SetItemsProcessed(static_cast<std::int64_t>(sent));
  state.counters["failed"] = static_cast<double>(failed);
}

void BM_SendTo(benchmark::State& state) {
  Fixture& f = fixture();
  const auto batch = static_cast<std::size_t>(state.range(0));
  std::size_t sent = 0, failed = 0, next = 0;
  for (auto _ : state) {
    for (std::size_t i = 0; i < batch; ++i, next = (next + 1) % kReceivers) {
      const ssize_t n = ::sendto(f.sender, f.payload.data(), f.payload.size(), 0,
                                 reinterpret_cast<const sockaddr*>(&f.to[next]), sizeof f.to[next]);
      n > 0 ? ++sent : ++failed;
    }
  }
  count(state, sent, failed);
}

void BM_SendMmsg(benchmark::State& state) {
  Fixture& f = fixture();
  const auto batch = static_cast<std::size_t>(state.range(0));
  std::vector<mmsghdr> msgs(batch);
  std::vector<iovec> iovs(batch);
  std::size_t sent = 0, failed = 0, next = 0;
  for (auto _ : state) {
    for (std::size_t i = 0; i < batch; ++i, next = (next + 1) % kReceivers) {
      describe(f, f.to[next], msgs[i].msg_hdr, iovs[i]);
    }
    for (std::size_t done = 0; done < batch;) {
      const int n = ::sendmmsg(f.sender, msgs.data() + done, static_cast<unsigned>(batch - done), MSG_DONTWAIT);
      if (n <= 0) {  // this entry failed on its own: skip it, as the server does
        ++failed;
        ++done;
        continue;
      }
      sent += static_cast<std::size_t>(n);
      done += static_cast<std::size_t>(n);
    }
  }
  count(state, sent, failed);
}

void BM_IoUring(benchmark::State& state) {
  Fixture& f = fixture();
  const auto batch = static_cast<std::size_t>(state.range(0));
  io_uring ring{};
  const int err = io_uring_queue_init(static_cast<unsigned>(batch), &ring, 0);
  if (err < 0) {
    state.SkipWithError(("io_uring_queue_init: " + std::string(std::strerror(-err))).c_str());
    return;
  }
  std::vector<msghdr> msgs(batch);
  std::vector<iovec> iovs(batch);
  std::size_t sent = 0, failed = 0, next = 0;
  for (auto _ : state) {
    for (std::size_t i = 0; i < batch; ++i, next = (next + 1) % kReceivers) {
      describe(f, f.to[next], msgs[i], iovs[i]);
      io_uring_sqe* sqe = io_uring_get_sqe(&ring);
      io_uring_prep_sendmsg(sqe, f.sender, &msgs[i], MSG_DONTWAIT);
    }
    io_uring_submit_and_wait(&ring, static_cast<unsigned>(batch));
    io_uring_cqe* cqe = nullptr;
    unsigned head = 0, seen = 0;
    io_uring_for_each_cqe(&ring, head, cqe) {
      cqe->res > 0 ? ++sent : ++failed;
      ++seen;
    }
    io_uring_cq_advance(&ring, seen);
  }
  io_uring_queue_exit(&ring);
  count(state, sent, failed);
}

// The process's CPU time, so that work io_uring hands to kernel worker
// threads is counted too.
BENCHMARK(BM_SendTo)->Name("udp/sendto")->Arg(256)->MeasureProcessCPUTime();
BENCHMARK(BM_SendMmsg)->Name("udp/sendmmsg")->Arg(16)->Arg(256)->MeasureProcessCPUTime();
BENCHMARK(BM_IoUring)->Name("udp/io_uring")->Arg(16)->Arg(256)->MeasureProcessCPUTime();

}  // namespace

BENCHMARK_MAIN();
