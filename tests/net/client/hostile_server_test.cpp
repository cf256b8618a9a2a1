// The C++ client and the `gmr` command against a server that misbehaves:
// one that closes, resets, goes silent or sends garbage right after its
// HelloReply (closing the client still returns at once), and one that sends
// counts and indices that do not fit (frames with too few values, joint
// indices past the skeleton, names with terminal escapes). Nothing a server
// sends may crash, hang or reach the terminal raw.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "gmr/client/client.h"
#include "gmr/wire/framing.h"
#include "net_test_util.h"

namespace gmr::test {
namespace {

using Clock = std::chrono::steady_clock;

// What the fake server does once it has answered Hello.
enum class AfterHello { kServe, kClose, kReset, kGarbage, kHugePrefix, kSilent };

const char* name_of(AfterHello a) {
  switch (a) {
    case AfterHello::kServe:
      return "serve";
    case AfterHello::kClose:
      return "close";
    case AfterHello::kReset:
      return "reset";
    case AfterHello::kGarbage:
      return "garbage";
    case AfterHello::kHugePrefix:
      return "a 4 GiB length prefix";
    case AfterHello::kSilent:
      return "silence";
  }
  return "?";
}

// A server on 127.0.0.1 that speaks just enough of the protocol: Hello, then
// `after`; with kServe, each request goes to `answer`, whose messages are
// sent in order (request ids are the answer's to set): each in a send of its
// own, or with `cut` all of an answer's bytes in sends of `cut` bytes.
// Connections are served one at a time, each until the client goes or `stop()`.
class FakeServer {
 public:
  using Answer = std::function<std::vector<pb::ServerMessage>(const pb::ClientMessage&)>;

  explicit FakeServer(AfterHello after, Answer answer = {}, std::size_t cut = 0)
      : after_(after), answer_(std::move(answer)), cut_(cut) {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    EXPECT_EQ(::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
    EXPECT_EQ(::listen(listen_fd_, 16), 0);
    socklen_t len = sizeof addr;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
    port_ = ntohs(addr.sin_port);
    thread_ = std::thread([this] { run(); });
  }
  ~FakeServer() {
    stopping_ = true;
    thread_.join();
    ::close(listen_fd_);
  }
  std::uint16_t port() const { return port_; }
  int connections() const { return connections_; }

 private:
  // Waits up to 50 ms for `fd` to be readable; false when stopping.
  bool wait_readable(int fd) {
    while (!stopping_) {
      pollfd p{fd, POLLIN, 0};
      if (::poll(&p, 1, 50) > 0) return true;
    }
    return false;
  }
  bool read_exact(int fd, char* out, std::size_t n) {
    while (n > 0) {
      if (!wait_readable(fd)) return false;
      const ssize_t got = ::recv(fd, out, n, 0);
      if (got <= 0) return false;
      out += got;
      n -= static_cast<std::size_t>(got);
    }
    return true;
  }
  bool read_message(int fd, pb::ClientMessage& m) {
    std::array<std::uint8_t, wire::kLengthPrefixBytes> prefix{};
    if (!read_exact(fd, reinterpret_cast<char*>(prefix.data()), prefix.size())) return false;
    std::string body(wire::read_length_prefix(prefix), '\0');
    return read_exact(fd, body.data(), body.size()) && m.ParseFromString(body);
  }
  static void send_bytes(int fd, const std::string& bytes) {
    (void)::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
  }
  void run() {
    while (!stopping_) {
      if (!wait_readable(listen_fd_)) return;
      const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
      if (fd < 0) continue;
      ++connections_;
      serve(fd);
    }
  }
  void serve(int fd) {
    pb::ClientMessage hello;
    if (!read_message(fd, hello)) {
      ::close(fd);
      return;
    }
    pb::ServerMessage reply;
    reply.set_request_id(hello.request_id());
    reply.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
    reply.mutable_hello()->set_server_name("fake");
    reply.mutable_hello()->set_max_message_bytes(1 << 20);
    reply.mutable_hello()->set_heartbeat_interval_ms(60000);
    reply.mutable_hello()->set_idle_timeout_ms(60000);
    send_bytes(fd, wire::frame_message(reply).value());
    switch (after_) {
      case AfterHello::kClose:
        break;
      case AfterHello::kReset: {
        linger l{1, 0};  // close sends RST
        ::setsockopt(fd, SOL_SOCKET, SO_LINGER, &l, sizeof l);
        break;
      }
      case AfterHello::kGarbage:
        send_bytes(fd, std::string("\x00\x00\x00\x10this is no protobuf", 23));
        break;
      case AfterHello::kHugePrefix:
        send_bytes(fd, std::string("\xff\xff\xff\xff", 4));
        break;
      case AfterHello::kSilent:
        while (wait_readable(fd)) {
          std::array<char, 4096> sink{};
          if (::recv(fd, sink.data(), sink.size(), 0) <= 0) break;
        }
        break;
      case AfterHello::kServe:
        if (cut_ != 0) {
          const int on = 1;  // each cut goes out as it is sent
          ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &on, sizeof on);
        }
        for (pb::ClientMessage m; read_message(fd, m);) {
          if (m.has_heartbeat()) continue;
          std::string bytes;
          for (const auto& out : answer_(m)) {
            if (cut_ == 0) send_bytes(fd, wire::frame_message(out).value());
            bytes += wire::frame_message(out).value();
          }
          for (std::size_t at = 0; cut_ != 0 && at < bytes.size(); at += cut_) send_bytes(fd, bytes.substr(at, cut_));
        }
        break;
    }
    ::close(fd);
  }

  AfterHello after_;
  Answer answer_;
  std::size_t cut_;
  int listen_fd_ = -1;
  std::uint16_t port_ = 0;
  std::thread thread_;
  std::atomic<bool> stopping_{false};
  std::atomic<int> connections_{0};
};

client::ClientOptions options_for(std::uint16_t port) {
  client::ClientOptions o;
  o.host = "127.0.0.1";
  o.port = port;
  o.timeout = std::chrono::milliseconds(500);
  return o;
}

TEST(HostileServer, ClosingAClientReturnsAtOnceWhateverTheServerDidAfterHello) {
  // Before the fix, a client whose server went away right after HelloReply
  // waited for ever in its destructor in 2-4 of 6 runs (`gmr ls`, `gmr stream`).
  constexpr int kRuns = 8;
  double worst = 0;
  int connected = 0;
  for (const AfterHello after :
       {AfterHello::kClose, AfterHello::kReset, AfterHello::kGarbage, AfterHello::kHugePrefix, AfterHello::kSilent}) {
    SCOPED_TRACE(name_of(after));
    FakeServer server(after);
    for (int run = 0; run < kRuns; ++run) {
      auto c = client::Client::connect(options_for(server.port()));
      if (!c.ok()) continue;  // it may fail during the handshake: that is an answer too
      ++connected;
      // A request meets the failed connection or times out: either way an error.
      auto motions = (*c)->list_motions();
      EXPECT_FALSE(motions.ok());
      const auto start = Clock::now();
      c->reset();
      const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
      worst = std::max(worst, seconds);
      EXPECT_LT(seconds, 1.0) << "closing the client took " << seconds << " s (run " << run << ")";
    }
    EXPECT_EQ(server.connections(), kRuns);
  }
  EXPECT_GT(connected, 0);
  std::fprintf(stderr, "hostile server: %d clients connected and closed, the slowest close took %.3f s\n", connected,
               worst);
}

// A four-joint chain as a server sends it; `first_name` names the root.
pb::Skeleton chain(const std::string& first_name = "Hips") {
  pb::Skeleton s;
  const std::array<std::string, 4> names{first_name, "Spine", "Neck", "Head"};
  for (int j = 0; j < 4; ++j) {
    auto* joint = s.add_joints();
    joint->set_name(names[static_cast<std::size_t>(j)]);
    joint->set_parent(j - 1);
    joint->set_soft_parent(-1);
    joint->mutable_offset()->set_y(j == 0 ? 0.0 : 10.0);
  }
  return s;
}

pb::ServerMessage frame_with(int positions, std::uint64_t index, std::uint64_t sequence, bool orientations) {
  pb::ServerMessage m;
  auto* f = m.mutable_frame();
  f->set_view_id(1);
  f->set_subscription_id(7);
  f->set_skeleton_version(1);
  f->set_frame_index(index);
  f->set_sequence(sequence);
  f->set_server_send_time_ns(
      std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
          .count());
  for (int i = 0; i < positions * 3; ++i) f->add_positions_f64(static_cast<double>(i));
  for (int i = 0; orientations && i < positions; ++i) {
    f->add_orientations_f64(0);
    f->add_orientations_f64(0);
    f->add_orientations_f64(0);
    f->add_orientations_f64(1);
  }
  return m;
}

// A server for `gmr stream` and `gmr record`: one motion of a four-joint
// chain whose root is `root_name`, a subscription naming `joints`, then the
// frames of `frames` (position counts) and the end.
FakeServer::Answer stream_server(std::string root_name, std::vector<std::uint32_t> joints, std::vector<int> frames,
                                 std::uint64_t sequence_step = 1) {
  return [=](const pb::ClientMessage& m) {
    std::vector<pb::ServerMessage> out(1);
    pb::ServerMessage& r = out[0];
    r.set_request_id(m.request_id());
    if (m.has_list_motions()) {
      auto* info = r.mutable_motions()->add_motions();
      info->set_name(root_name);
      info->set_joint_count(4);
      info->set_frame_count(10);
      info->set_frame_time(0.1);
      info->set_source(
          "\x1b]0;owned\x07"
          "file.bvh");
    } else if (m.has_get_skeleton()) {
      r.mutable_skeleton()->set_motion(m.get_skeleton().motion());
      *r.mutable_skeleton()->mutable_skeleton() = chain(root_name);
    } else if (m.has_create_view()) {
      auto* v = r.mutable_view();
      v->set_view_id(1);
      v->set_motion(m.create_view().motion());
      v->set_skeleton_version(1);
      *v->mutable_skeleton() = chain(root_name);
      v->set_frame_count(10);
      v->set_frame_time(0.1);
    } else if (m.has_subscribe()) {
      auto* s = r.mutable_subscribed();
      s->set_subscription_id(7);
      s->set_view_id(1);
      s->set_skeleton_version(1);
      for (auto j : joints) s->add_joints(j);
      s->set_rate_hz(10);
      *s->mutable_skeleton() = chain(root_name);
      std::uint64_t sequence = 0;
      for (std::size_t k = 0; k < frames.size(); ++k, sequence += sequence_step) {
        out.push_back(frame_with(frames[k], k, sequence, m.subscribe().orientations()));
      }
      pb::ServerMessage end;
      end.mutable_subscription_ended()->set_subscription_id(7);
      end.mutable_subscription_ended()->set_frames_sent(frames.size());
      end.mutable_subscription_ended()->set_reason("end of motion\x1b[2J");
      out.push_back(end);
    } else if (m.has_unsubscribe()) {
      r.mutable_ack();
    } else {
      r.mutable_error()->set_code(pb::ERROR_CODE_BAD_REQUEST);
      r.mutable_error()->set_message("not in this fake");
    }
    return out;
  };
}

// Subscribes to a view of motion "m" (float64, no staleness bound), hands
// each frame to `on_frame` (on the client's thread) and waits up to `wait`
// for the subscription to end.
::testing::AssertionResult stream_to_end(client::Client& c,
                                         const std::function<void(const client::ReceivedFrame&)>& on_frame,
                                         std::chrono::seconds wait) {
  auto v = c.create_view("m");
  if (!v.ok()) return ::testing::AssertionFailure() << v.error().to_string();
  // Shared with the callback, which may outlive this call if the end is late.
  auto ended = std::make_shared<Latch<client::SubscriptionEnd>>();
  client::SubscribeOptions o;
  o.float64 = true;
  o.max_staleness = std::chrono::milliseconds(0);
  auto sub = c.subscribe(v->id, o, on_frame, [ended](const client::SubscriptionEnd& e) { ended->set(e); });
  if (!sub.ok()) return ::testing::AssertionFailure() << sub.error().to_string();
  if (!ended->wait(wait).has_value()) return ::testing::AssertionFailure() << "the subscription did not end";
  return ::testing::AssertionSuccess();
}

TEST(HostileServer, FramesWhoseValuesDoNotFitTheSubscriptionAreDroppedAndCounted) {
  FakeServer server(AfterHello::kServe, stream_server("Hips", {0, 1, 2, 3}, {0, 1, 4, 5, 4}));
  auto c = client::Client::connect(options_for(server.port()));
  ASSERT_TRUE(c.ok()) << c.error().to_string();
  std::mutex mutex;
  std::vector<std::size_t> sizes;
  ASSERT_TRUE(stream_to_end(
      **c,
      [&](const client::ReceivedFrame& f) {
        std::lock_guard lock(mutex);
        sizes.push_back(f.positions.size());
      },
      std::chrono::seconds(5)));
  std::lock_guard lock(mutex);
  EXPECT_EQ(sizes, (std::vector<std::size_t>{4, 4}));  // the frames of 0, 1 and 5 positions never arrive
  EXPECT_EQ((*c)->counters().frames_malformed, 3u);
}

// The client reads what arrived and takes every whole message from it: many
// messages in one read, a message over several, one longer than a read (5 KB
// in small cuts, 200 KB past the kept buffer in large ones), in every cut.
TEST(HostileServer, MessagesArriveWholeHoweverTheBytesAreCut) {
  int cuts = 0;
  for (const std::size_t cut :
       {std::size_t{0}, std::size_t{1}, std::size_t{3}, std::size_t{1000}, std::size_t{65536}}) {
    SCOPED_TRACE("cut " + std::to_string(cut));
    const std::string long_source(cut != 0 && cut < 1000 ? 5'000 : 200'000, 's');
    const std::vector<int> frames(40, 4);
    auto answer = stream_server("Hips", {0, 1, 2, 3}, frames);
    FakeServer server(
        AfterHello::kServe,
        [&](const pb::ClientMessage& m) {
          auto out = answer(m);
          if (m.has_list_motions()) out[0].mutable_motions()->mutable_motions(0)->set_source(long_source);
          return out;
        },
        cut);
    auto c = client::Client::connect(options_for(server.port()));
    ASSERT_TRUE(c.ok()) << c.error().to_string();
    auto motions = (*c)->list_motions();
    ASSERT_TRUE(motions.ok()) << motions.error().to_string();
    ASSERT_EQ(motions->size(), 1u);
    EXPECT_EQ(motions->front().source, long_source);
    std::mutex mutex;
    std::vector<std::uint64_t> indices;
    ASSERT_TRUE(stream_to_end(
        **c,
        [&](const client::ReceivedFrame& f) {
          std::lock_guard lock(mutex);
          EXPECT_EQ(f.positions.size(), 4u);
          EXPECT_EQ(f.positions[3], Eigen::Vector3d(9, 10, 11));
          indices.push_back(f.frame_index);
        },
        std::chrono::seconds(20)));
    std::lock_guard lock(mutex);
    ASSERT_EQ(indices.size(), frames.size());
    for (std::size_t k = 0; k < indices.size(); ++k) EXPECT_EQ(indices[k], k);
    EXPECT_EQ((*c)->counters().frames_malformed, 0u);
    ++cuts;
  }
  EXPECT_EQ(cuts, 5);
}

TEST(HostileServer, ASubscriptionNamingAJointPastTheSkeletonIsRefused) {
  FakeServer server(AfterHello::kServe, stream_server("Hips", {0, 1000000, 2, 3}, {4}));
  auto c = client::Client::connect(options_for(server.port()));
  ASSERT_TRUE(c.ok()) << c.error().to_string();
  auto v = (*c)->create_view("m");
  ASSERT_TRUE(v.ok());
  auto sub = (*c)->subscribe(v->id, client::SubscribeOptions{}, [](const client::ReceivedFrame&) {});
  ASSERT_FALSE(sub.ok());
  EXPECT_NE(sub.error().message.find("joint index 1000000 of a skeleton of 4 joints"), std::string::npos)
      << sub.error().message;
}

CommandRun gmr(const std::string& args) { return run_command(std::string(GMR_CLI_PATH) + " " + args); }

TEST(HostileServer, TheCommandChecksEveryCountAndEscapesEveryName) {
  // Before: `gmr stream` read positions[j] for every joint of the view
  // whatever the frame held (0 positions: a segfault; 1 of 4: heap memory as
  // CSV); `gmr record` segfaulted on joints [0, 1000000, 2, 3]; names with
  // ESC and BEL reached the terminal.
  const std::string esc_name = "Hips\x1b[31m\x07";
  {
    FakeServer server(AfterHello::kServe, stream_server(esc_name, {0, 1, 2, 3}, {0, 1, 4}));
    const CommandRun r = gmr("stream m --port " + std::to_string(server.port()));
    EXPECT_FALSE(r.signalled) << r.out;
    EXPECT_EQ(r.status, 1) << r.out;
    EXPECT_NE(r.out.find("2 frames from the server did not carry the 4 joints subscribed"), std::string::npos) << r.out;
    // The good frame printed, its root's name escaped.
    EXPECT_NE(r.out.find("2,Hips\\x1b[31m\\x07,0,1,2"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find('\x1b'), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find('\x07'), std::string::npos) << r.out;
  }
  {
    FakeServer server(AfterHello::kServe, stream_server("Hips", {0, 1000000, 2, 3}, {4, 4}));
    const std::string out = ::testing::TempDir() + "/hostile_record.gmr";
    const CommandRun r = gmr("record m -o '" + out + "' --port " + std::to_string(server.port()));
    EXPECT_FALSE(r.signalled) << r.out;
    EXPECT_EQ(r.status, 1) << r.out;
    EXPECT_NE(r.out.find("joint index 1000000 of a skeleton of 4 joints"), std::string::npos) << r.out;
  }
  {
    // A sequence that jumps by 2^40 is not a gap to fill with copies.
    FakeServer server(AfterHello::kServe, stream_server("Hips", {0, 1, 2, 3}, {4, 4}, std::uint64_t{1} << 40));
    const std::string out = ::testing::TempDir() + "/hostile_record.gmr";
    const CommandRun r = gmr("record m -o '" + out + "' --port " + std::to_string(server.port()));
    EXPECT_FALSE(r.signalled) << r.out;
    EXPECT_EQ(r.status, 1) << r.out;
    EXPECT_NE(r.out.find("the sequence jumped from 0 to 1099511627776"), std::string::npos) << r.out;
  }
  {
    FakeServer server(AfterHello::kServe, stream_server(esc_name, {0, 1, 2, 3}, {}));
    for (const std::string cmd : {"ls", "skeleton m"}) {
      const CommandRun r = gmr(cmd + " --port " + std::to_string(server.port()));
      SCOPED_TRACE(cmd);
      EXPECT_EQ(r.status, 0) << r.out;
      EXPECT_NE(r.out.find("Hips\\x1b[31m\\x07"), std::string::npos) << r.out;
      EXPECT_EQ(r.out.find('\x1b'), std::string::npos) << r.out;
      EXPECT_EQ(r.out.find('\x07'), std::string::npos) << r.out;
    }
  }
}

}  // namespace
}  // namespace gmr::test
