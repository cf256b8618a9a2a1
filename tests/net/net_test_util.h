// Loopback helpers for the server tests: an in-process server on 127.0.0.1
// port 0, a raw TCP connection that speaks bytes (for bad input), and a
// bounded wait. Nothing here sleeps; every wait has a deadline.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "gmr/client/client.h"
#include "gmr/server/server.h"
#include "gmr/stream/v1/stream.pb.h"

namespace gmr::test {

namespace pb = ::gmr::stream::v1;

// The demo library plus, when the corpus is there, cmu/02_01.bvh as "cmu/02_01".
std::vector<server::LibraryEntry> test_library();
// The BVH behind "cmu/02_01".
std::filesystem::path cmu_file();

// True in Debug and sanitizer builds, where the loopback machinery may be too
// slow to deliver every frame of a 1-2 kHz stream; tests then check that each
// frame is delivered or counted as dropped instead of that none is dropped.
#if defined(GMR_SANITIZED) || !defined(NDEBUG)
inline constexpr bool kSlowBuild = true;
#else
inline constexpr bool kSlowBuild = false;
#endif
// How long a client of a slow build waits for a reply (TestServer::connect,
// and `--timeout-ms` for the gmr commands the tests run), instead of 5 s.
inline constexpr std::chrono::milliseconds kSlowBuildReplyTimeout{30000};

// A server started on a free loopback port (TCP and UDP). Streams never skip
// frames to catch up (max_catch_up is an hour), and there is no send budget
// unless the test's configuration sets one other than the default.
struct TestServer {
  explicit TestServer(server::ServerConfig cfg = {}, std::vector<server::LibraryEntry> library = test_library());
  server::Server server;
  std::uint16_t port() const { return server.tcp_port(); }
  std::unique_ptr<client::Client> connect(client::ClientOptions o = {});
};

// A loopback listener that accepts connections (the kernel's backlog) and
// never answers: for a client's wait for a reply.
class SilentListener {
 public:
  SilentListener();
  ~SilentListener();
  SilentListener(const SilentListener&) = delete;
  SilentListener& operator=(const SilentListener&) = delete;
  std::uint16_t port() const { return port_; }

 private:
  int fd_ = -1;
  std::uint16_t port_ = 0;
};

// A blocking TCP connection with deadlines, for sending malformed bytes.
class RawConnection {
 public:
  explicit RawConnection(std::uint16_t port, int receive_buffer = 0);
  ~RawConnection();
  void send_bytes(const std::string& bytes);
  void send(const pb::ClientMessage& m);
  // The next server message, or nothing when the connection closed or the
  // deadline passed (closed() tells which).
  std::optional<pb::ServerMessage> receive(std::chrono::milliseconds timeout = std::chrono::seconds(5));
  // Next non-push reply (skips frames, heartbeats).
  std::optional<pb::ServerMessage> reply(std::chrono::milliseconds timeout = std::chrono::seconds(5));
  // True once the server closed the connection (read returned 0 or reset).
  bool wait_closed(std::chrono::milliseconds timeout = std::chrono::seconds(5));
  // Whether bytes from the server wait to be read (none is consumed).
  bool readable(std::chrono::milliseconds timeout);
  bool closed() const { return closed_; }
  void shutdown_send();
  // Hello + reply; returns the reply.
  pb::HelloReply handshake();
  // CreateView (request `id`) and its reply: the view's id, or nothing.
  std::optional<std::uint32_t> create_view(std::uint64_t id, const std::string& motion);

 private:
  bool read_exact(char* out, std::size_t n, std::chrono::steady_clock::time_point deadline);
  int fd_ = -1;
  bool closed_ = false;
};

// A self-signed certificate and its key (P-256), as PEM files in a
// directory of their own that goes with the object. `names` are its
// subjectAltName entries ("IP:127.0.0.1,DNS:localhost").
struct Certificate {
  std::filesystem::path dir, cert, key;
  ~Certificate();
};
std::unique_ptr<Certificate> self_signed(const std::string& names);

// A command line run through the shell, stdout captured and stderr merged
// into it: its exit status (-1 when it did not exit), whether a signal ended
// it, and what it printed.
struct CommandRun {
  int status = -1;
  bool signalled = false;
  std::string out;
};
CommandRun run_command(const std::string& command_line);

// A value that another thread sets; wait() has a deadline.
template <class T>
class Latch {
 public:
  void set(T v) {
    std::lock_guard lock(m_);
    if (!value_) value_ = std::move(v);
    cv_.notify_all();
  }
  void reset() {
    std::lock_guard lock(m_);
    value_.reset();
  }
  std::optional<T> wait(std::chrono::milliseconds timeout = std::chrono::seconds(20)) {
    std::unique_lock lock(m_);
    cv_.wait_for(lock, timeout, [&] { return value_.has_value(); });
    return value_;
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  std::optional<T> value_;
};

pb::ClientMessage request(std::uint64_t id);

// Streams every frame of the view once, one frame per tick at `rate_hz`, and
// returns the frames in arrival order (out_dropped: the server's drop count;
// no staleness bound, so every frame arrives or is counted there).
std::vector<client::ReceivedFrame> stream_all(client::Client& c, const client::ViewState& v, bool udp, bool float64,
                                              bool orientations, double rate_hz = 2000.0,
                                              std::uint64_t* out_dropped = nullptr);
// What a stream_all over TCP may miss: frames the server replaced (latest
// wins) while this process's reading thread was not scheduled, on a loaded
// machine or a sanitizer build; each is counted. Every frame was delivered
// or counted, and most were delivered. (A frame count at 2 kHz is a timing
// expectation: a test of content does not assert that none was replaced.)
void expect_delivered_or_counted(std::size_t delivered, std::uint64_t dropped, std::size_t total);

// A test per library motion (the parameter: "walk", or "cmu/02_01", which
// needs the shared data): a server, a connected client and the motion.
class LibraryMotionTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override;
  std::unique_ptr<TestServer> server_;
  std::unique_ptr<client::Client> client_;
  std::shared_ptr<const Motion> source_;
};

}  // namespace gmr::test
