// The C++ client against a server that says Hello and then stops reading:
// its requests pile up in the kernel, then in the client's write queue, and
// the queue's bound turns the next request into an immediate error instead
// of unbounded memory. And many clients on one shared EventLoop.
#include <arpa/inet.h>
#include <gtest/gtest.h>

#include <boost/asio.hpp>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "gmr/client/client.h"
#include "gmr/wire/framing.h"
#include "net_test_util.h"

namespace gmr::test {
namespace {

// Accepts one connection, answers its Hello, then reads nothing more until
// release().
class StubbornServer {
 public:
  StubbornServer() {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
    EXPECT_EQ(::listen(listen_fd_, 1), 0);
    socklen_t len = sizeof addr;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    thread_ = std::thread([this] { serve(); });
  }
  ~StubbornServer() {
    release();
    thread_.join();
    ::close(listen_fd_);
  }
  std::uint16_t port() const { return port_; }
  void release() {
    std::lock_guard lock(m_);
    released_ = true;
    cv_.notify_all();
  }

 private:
  static bool read_exact(int fd, char* out, std::size_t n) {
    while (n > 0) {
      const ssize_t got = ::recv(fd, out, n, 0);
      if (got <= 0) return false;
      out += got;
      n -= static_cast<std::size_t>(got);
    }
    return true;
  }
  void serve() {
    const int fd = ::accept(listen_fd_, nullptr, nullptr);
    if (fd < 0) return;
    std::array<std::uint8_t, wire::kLengthPrefixBytes> prefix{};
    std::string body;
    if (read_exact(fd, reinterpret_cast<char*>(prefix.data()), prefix.size())) {
      body.resize(wire::read_length_prefix(prefix));
      pb::ClientMessage hello;
      if (read_exact(fd, body.data(), body.size()) && hello.ParseFromString(body)) {
        pb::ServerMessage reply;
        reply.set_request_id(hello.request_id());
        reply.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
        reply.mutable_hello()->set_heartbeat_interval_ms(60000);
        reply.mutable_hello()->set_idle_timeout_ms(60000);
        const std::string bytes = wire::frame_message(reply).value();
        (void)::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
      }
    }
    std::unique_lock lock(m_);
    cv_.wait(lock, [&] { return released_; });
    ::close(fd);
  }

  int listen_fd_ = -1;
  std::uint16_t port_ = 0;
  std::thread thread_;
  std::mutex m_;
  std::condition_variable cv_;
  bool released_ = false;
};

TEST(ClientWriteQueue, IsBoundedWhenTheServerStopsReading) {
  StubbornServer server;
  client::ClientOptions o;
  o.host = "127.0.0.1";
  o.port = server.port();
  o.timeout = std::chrono::milliseconds(20);  // no reply will come: each request gives up quickly
  o.max_write_queue_bytes = 1 << 20;
  auto c = client::Client::connect(o);
  ASSERT_TRUE(c.ok()) << c.error().to_string();
  const std::string big(256 << 10, 'x');  // 256 KiB of motion name per request
  int requests = 0;
  Result<client::ViewState> last = make_error("not sent");
  // The kernel's buffers take a few MiB; then the queue fills to its bound.
  for (; requests < 400; ++requests) {
    last = (*c)->create_view(big);
    if (!last.ok() && last.error().kind == ErrorKind::kResourceExhausted) break;
  }
  ASSERT_LT(requests, 400) << "the write queue never refused a request: " << last.error().to_string();
  EXPECT_NE(last.error().message.find("write queue full"), std::string::npos) << last.error().message;
  EXPECT_TRUE((*c)->connected());  // refused, not disconnected
  server.release();
}

// 200 clients on one EventLoop of two threads (not a thread each): every one
// connects, subscribes and gets all its frames, with its callbacks never
// running two at a time; a client can close itself from its own callback;
// the rest close, then the loop goes.
TEST(EventLoop, ManyClientsShareTwoThreads) {
  server::ServerConfig cfg;
  cfg.max_connections = 512;
  cfg.max_connections_per_address = 0;
  TestServer s(cfg);
  auto loop = std::make_shared<client::EventLoop>(2);
  EXPECT_EQ(loop->threads(), 2u);
  constexpr int kClients = 200;
  constexpr int kFrames = 20;
  struct Counts {
    std::atomic<int> frames{0};
    std::atomic<int> inside{0};  // callbacks of this client running now
    std::atomic<bool> overlapped{false};
    std::atomic<bool> ended{false};
  };
  std::vector<Counts> counts(kClients);
  std::vector<std::unique_ptr<client::Client>> clients;
  client::ClientOptions o;
  o.port = s.port();
  o.loop = loop;
  for (int i = 0; i < kClients; ++i) {
    auto c = client::Client::connect(o);
    ASSERT_TRUE(c.ok()) << i << ": " << c.error().to_string();
    clients.push_back(std::move(c).value());
  }
  const auto started = std::chrono::steady_clock::now();
  for (int i = 0; i < kClients; ++i) {
    auto v = clients[static_cast<std::size_t>(i)]->create_view("walk");
    ASSERT_TRUE(v.ok());
    client::SubscribeOptions so;
    so.end_frame = kFrames;
    so.speed = 2;  // the motion's frames once each, at twice its rate
    Counts& k = counts[static_cast<std::size_t>(i)];
    auto sub = clients[static_cast<std::size_t>(i)]->subscribe(
        v->id, so,
        [&k](const client::ReceivedFrame&) {
          if (k.inside.fetch_add(1) != 0) k.overlapped = true;
          std::this_thread::sleep_for(std::chrono::microseconds(50));
          ++k.frames;
          k.inside.fetch_sub(1);
        },
        [&k](const client::SubscriptionEnd&) { k.ended = true; });
    ASSERT_TRUE(sub.ok()) << sub.error().to_string();
  }
  for (auto& k : counts) {
    while (!k.ended && std::chrono::steady_clock::now() - started < std::chrono::seconds(30)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  }
  int complete = 0;
  for (auto& k : counts) {
    complete += k.ended && k.frames == kFrames;
    EXPECT_FALSE(k.overlapped) << "a client's callbacks ran at the same time on two threads";
  }
  EXPECT_EQ(complete, kClients);

  // A client that closes itself from its callback, on a loop thread.
  auto v = clients[0]->create_view("wave");
  ASSERT_TRUE(v.ok());
  std::atomic<bool> closed_inside{false};
  client::Client* first = clients[0].get();
  client::SubscribeOptions looping;
  looping.loop = true;
  ASSERT_TRUE(first
                  ->subscribe(v->id, looping,
                              [&](const client::ReceivedFrame&) {
                                if (!closed_inside.exchange(true)) first->close();
                              })
                  .ok());
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!closed_inside && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_TRUE(closed_inside);
  clients.clear();  // closes every client, then the loop can go
  loop.reset();
}

// The caller's own io_context, run by the caller on one thread: 20 clients
// on it stream; closing them from the main thread does not wait for ever.
TEST(EventLoop, RunsOnTheCallersIoContext) {
  TestServer s;
  boost::asio::io_context io;
  auto work = boost::asio::make_work_guard(io);
  std::thread runner([&io] { io.run(); });
  auto loop = std::make_shared<client::EventLoop>(io);
  EXPECT_EQ(loop->threads(), 0u);
  client::ClientOptions o;
  o.port = s.port();
  o.loop = loop;
  std::vector<std::unique_ptr<client::Client>> clients;
  std::atomic<int> ended{0}, frames{0};
  for (int i = 0; i < 20; ++i) {
    auto c = client::Client::connect(o);
    ASSERT_TRUE(c.ok()) << c.error().to_string();
    auto v = (*c)->create_view("jump");
    ASSERT_TRUE(v.ok());
    client::SubscribeOptions so;
    so.end_frame = 10;
    so.speed = 4;
    ASSERT_TRUE((*c)->subscribe(
                        v->id, so, [&](const client::ReceivedFrame&) { ++frames; },
                        [&](const client::SubscriptionEnd&) { ++ended; })
                    .ok());
    clients.push_back(std::move(c).value());
  }
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (ended < 20 && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  EXPECT_EQ(ended.load(), 20);
  EXPECT_EQ(frames.load(), 200);
  clients.clear();
  loop.reset();
  work.reset();
  runner.join();
}

}  // namespace
}  // namespace gmr::test
