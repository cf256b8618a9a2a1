// What clients can make the server hold (docs/protocol.md, "Memory budget"):
// 64 clients that edit views, subscribe at high rates and never read stay
// within the server's stated budget, and a well-behaved client meanwhile
// keeps its rate.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <fstream>
#include <mutex>
#include <thread>

#include "gmr/wire/framing.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

// The resident set of this process, in bytes (0 when /proc is not there).
std::uint64_t resident_bytes() {
  std::ifstream in("/proc/self/status");
  std::string key;
  while (in >> key) {
    if (key == "VmRSS:") {
      std::uint64_t kb = 0;
      in >> kb;
      return kb * 1024;
    }
    std::string rest;
    std::getline(in, rest);
  }
  return 0;
}

// Pushes as much of `bytes` down each socket of `fds` as the kernel takes,
// for two seconds; `sent[i]`: how much of it socket i took.
void push_for_two_seconds(const std::vector<int>& fds, const std::string& bytes, std::vector<std::size_t>& sent) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(2);
  while (std::chrono::steady_clock::now() < until) {
    for (std::size_t i = 0; i < fds.size(); ++i) {
      if (sent[i] == bytes.size()) continue;
      const ssize_t n = ::send(fds[i], bytes.data() + sent[i], bytes.size() - sent[i], MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n > 0) sent[i] += static_cast<std::size_t>(n);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

struct Refusals {
  int views = 0;  // RESOURCE_EXHAUSTED edits
};

// One client that never reads frames: `views` views, each re-rooted (so each
// would hold its own copy of the motion), then `subscriptions` subscriptions
// over them at 2 kHz, float64 with orientations. It reads only the replies
// to its edits (the frames pile up behind them).
Refusals never_reading_client(RawConnection& c, const std::string& motion, const std::vector<std::string>& joints,
                              int views, int subscriptions) {
  Refusals out;
  c.handshake();
  std::uint64_t id = 10;
  std::vector<std::uint32_t> view_ids;
  for (int v = 0; v < views; ++v) {
    auto m = request(id++);
    m.mutable_create_view()->set_motion(motion);
    c.send(m);
    auto r = c.reply();
    if (!r || !r->has_view()) {
      ADD_FAILURE() << "create_view: " << (r ? r->DebugString() : "no reply");
      return out;
    }
    view_ids.push_back(r->view().view_id());
    auto shift = request(id++);
    shift.mutable_shift_root()->set_view_id(view_ids.back());
    shift.mutable_shift_root()->set_joint(joints[static_cast<std::size_t>(v) % joints.size()]);
    c.send(shift);
    auto e = c.reply();
    if (e && e->has_error()) {
      EXPECT_EQ(e->error().code(), pb::ERROR_CODE_RESOURCE_EXHAUSTED) << e->error().message();
      if (e->error().code() == pb::ERROR_CODE_RESOURCE_EXHAUSTED) ++out.views;
    } else {
      EXPECT_TRUE(e && e->has_view());
    }
  }
  for (int s = 0; s < subscriptions; ++s) {
    auto sub = request(id++);
    sub.mutable_subscribe()->set_view_id(view_ids[static_cast<std::size_t>(s) % view_ids.size()]);
    sub.mutable_subscribe()->set_loop(true);
    sub.mutable_subscribe()->set_rate_hz(2000);
    sub.mutable_subscribe()->set_orientations(true);
    sub.mutable_subscribe()->set_precision(pb::PRECISION_FLOAT64);
    c.send(sub);
  }
  return out;
}

TEST(Memory, ClientsThatNeverReadStayWithinTheBudgetAndAGoodClientKeepsItsRate) {
  GMR_REQUIRE_DATA();  // a real motion: CMU 02_01, 344 frames, 96 channels
  // Sanitizer and Debug builds run an eighth of the clients, against a smaller
  // view limit (the same refusals, a fraction of the time).
  constexpr int kClients = kSlowBuild ? 8 : 64, kViews = kSlowBuild ? 8 : 32, kSubscriptions = kSlowBuild ? 8 : 32;
  server::ServerConfig cfg;
  cfg.max_view_bytes = kSlowBuild ? 4u << 20 : 24u << 20;
  cfg.max_view_bytes_per_connection = 4u << 20;
  cfg.max_buffered_bytes = 16u << 20;
  cfg.max_connections_per_address = 0;  // every client is on 127.0.0.1
  // The slow clients stay connected for the whole test: a slow build takes
  // longer than the default write and idle timeouts to set them all up, and a
  // client closed early would give its views back before they are counted.
  cfg.write_timeout = std::chrono::minutes(10);
  cfg.idle_timeout = std::chrono::minutes(10);
  TestServer s(cfg);
  const std::uint64_t before = resident_bytes();

  std::vector<std::unique_ptr<RawConnection>> slow;
  int refused = 0;
  for (int i = 0; i < kClients; ++i) {
    slow.push_back(std::make_unique<RawConnection>(s.port(), 4096));
    refused += never_reading_client(*slow.back(), "cmu/02_01", {"Head", "LeftHand"}, kViews, kSubscriptions).views;
  }
  // Each edited view owns a copy of 344 frames (about 0.2 MB at 16 bytes a
  // value): 20 fit in a connection's 4 MiB, the server's 24 MiB hold about
  // 128 (its 4 MiB in slow builds, 20), and every other edit was refused.
  const auto mid = s.server.stats();
  EXPECT_LE(mid.view_bytes, cfg.max_view_bytes);
  EXPECT_GT(mid.view_bytes, cfg.max_view_bytes - (1u << 20));
  EXPECT_GT(refused, kClients * kViews / 2);

  // The well-behaved client: 60 Hz for 3 s, every frame, on time.
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("cmu/02_01");
  ASSERT_TRUE(v.ok());
  std::mutex mu;
  std::vector<std::uint64_t> seq;
  client::SubscribeOptions o;
  o.loop = true;
  o.rate_hz = 60;
  o.max_frames = 180;
  Latch<client::SubscriptionEnd> ended;
  const auto start = std::chrono::steady_clock::now();
  ASSERT_TRUE(c->subscribe(
                   v->id, o,
                   [&](const client::ReceivedFrame& f) {
                     std::lock_guard lock(mu);
                     seq.push_back(f.sequence);
                   },
                   [&](const client::SubscriptionEnd& e) { ended.set(e); })
                  .ok());
  std::uint64_t peak = resident_bytes();
  std::optional<client::SubscriptionEnd> end;
  while (!(end = ended.wait(std::chrono::milliseconds(50)))) {
    peak = std::max(peak, resident_bytes());
    if (std::chrono::steady_clock::now() - start > std::chrono::seconds(30)) break;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(end.has_value());
  const auto st = s.server.stats();
  std::uint64_t slow_dropped = 0;
  for (const auto& ss : st.sessions) slow_dropped += ss.frames_dropped;
  std::printf(
      "RSS %.1f MB before, %.1f MB at the peak; views %.1f MB, buffers at most %.1f MB; "
      "good client: %zu frames in %.2f s; slow clients: %llu frames dropped\n",
      static_cast<double>(before) / 1e6, static_cast<double>(peak) / 1e6, static_cast<double>(st.view_bytes) / 1e6,
      static_cast<double>(st.max_buffered_bytes) / 1e6, seq.size(), seconds,
      static_cast<unsigned long long>(slow_dropped));

  // The good client: every frame in order at its rate, or (a busy machine)
  // counted as given up, which may be a few.
  const std::uint64_t gone = end->frames_dropped + end->frames_skipped;
  EXPECT_EQ(seq.size() + gone, 180u);
  EXPECT_LE(gone, 18u);
  for (std::size_t k = 1; k < seq.size(); ++k) EXPECT_GT(seq[k], seq[k - 1]);
  if (!seq.empty()) {
    EXPECT_LT(seq.back(), 180u);
  }
  if (!kSlowBuild) {
    EXPECT_LT(seconds, 3.0 * 1.15) << "60 Hz for 180 frames is 3 s";
  }
  EXPECT_GT(slow_dropped, 0u);

  // The budget: what the server accounts, and what the process holds.
  EXPECT_LE(st.max_buffered_bytes, cfg.max_buffered_bytes + cfg.max_reply_queue_bytes + (1u << 20));
  // Resident growth: views and buffers within their limits, plus per
  // subscription state (docs/protocol.md: at most 64 KB each). Sanitizers
  // add their own shadow memory and quarantine: checked in Release only.
  const std::uint64_t budget =
      cfg.max_view_bytes + cfg.max_buffered_bytes + std::uint64_t{kClients} * kSubscriptions * 64 * 1024;
  if (!kSlowBuild) {
    EXPECT_LT(peak - before, budget) << "the server held more than its budget";
  }
}

TEST(Memory, AFloatStreamOfChannelLessFramesComputesOneFrame) {
  // Ten roots without channels declaring 2^24 frames (a 450-byte BVH, loaded
  // here with the joint-frame limit raised): the first float32 subscription
  // compiles one frame of positions, not 2 GB of copies of it.
  std::vector<Joint> roots;
  for (int j = 0; j < 10; ++j) {
    Joint r;
    r.name = "r";
    r.name += std::to_string(j);  // (GCC 12's -Wrestrict misfires on "r" + std::to_string(j) here)
    r.offset = Eigen::Vector3d(j, 1, 0);
    roots.push_back(r);
  }
  auto m = std::make_shared<Motion>();
  m->skeleton = Skeleton::create(std::move(roots)).value();
  m->frame_count = std::size_t{1} << 24;
  m->frame_time = 0.01;
  server::LibraryEntry entry;
  entry.name = "huge";
  entry.source = "huge.bvh";
  entry.motion = m;
  TestServer s({}, {entry});
  const std::uint64_t before = resident_bytes();
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("huge");
  ASSERT_TRUE(v.ok());
  std::mutex mu;
  std::vector<client::ReceivedFrame> frames;
  Latch<client::SubscriptionEnd> ended;
  client::SubscribeOptions o;
  o.start_frame = static_cast<std::uint32_t>(m->frame_count - 3);
  ASSERT_TRUE(c->subscribe(
                   v->id, o,
                   [&](const client::ReceivedFrame& f) {
                     std::lock_guard lock(mu);
                     frames.push_back(f);
                   },
                   [&](const client::SubscriptionEnd& e) { ended.set(e); })
                  .ok());
  ASSERT_TRUE(ended.wait().has_value());
  ASSERT_EQ(frames.size(), 3u);
  for (const auto& f : frames) {
    ASSERT_EQ(f.positions.size(), 10u);
    EXPECT_EQ(f.positions[9], Eigen::Vector3d(9, 1, 0));
  }
  EXPECT_GT(s.server.stats().frames_computed_float, 0u);
  if (!kSlowBuild) {
    EXPECT_LT(resident_bytes() - before, 64u << 20);
  }
}

TEST(Memory, DeclaredLengthsReserveNothing) {
  // 250 connections each announce a message just under the 4 MiB limit and
  // send 10 bytes of it: the server holds what arrived, not what was announced.
  server::ServerConfig cfg;
  cfg.max_connections_per_address = 0;  // every client is on 127.0.0.1
  cfg.max_pending_handshakes = 300;     // and none says Hello
  TestServer s(cfg);
  const std::uint64_t before = resident_bytes();
  std::vector<std::unique_ptr<RawConnection>> conns;
  const std::uint32_t length = wire::kDefaultMaxMessageBytes - 1;
  std::string prefix(4, '\0');
  for (int i = 0; i < 4; ++i) prefix[static_cast<std::size_t>(i)] = static_cast<char>(length >> (24 - 8 * i));
  for (int i = 0; i < 250; ++i) {
    conns.push_back(std::make_unique<RawConnection>(s.port()));
    conns.back()->send_bytes(prefix + std::string(10, 'x'));
  }
  // A well-behaved client is still served, and sees all 251 connections.
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  ASSERT_TRUE(c->list_motions().ok());
  const auto st = s.server.stats();
  EXPECT_EQ(st.connections, 251u);
  // (plus what the good client may have in flight)
  EXPECT_LE(st.buffered_bytes, 250u * 4096 + 64 * 1024) << "bodies are held as they arrive";
  const std::uint64_t grown = resident_bytes() - before;
  std::printf("250 announced 4 MiB bodies: server buffers %llu bytes, RSS grew %.1f MB\n",
              static_cast<unsigned long long>(st.buffered_bytes), static_cast<double>(grown) / 1e6);
  if (!kSlowBuild) {
    EXPECT_LT(grown, 16u << 20);
  }
}

// Before: an 875-byte channel-less BVH (a 30-joint chain, 2^20 frames) and
// one SetRoots of its 30 joints took 4.29 GB and about 10 s, no client
// answered meanwhile, before the view limit was checked on the copy. The
// edit's output is now bounded from frames x channels before anything is
// computed, and refused with the figures.
TEST(Memory, AnEditThatWouldExplodeIsRefusedBeforeItIsComputed) {
  std::vector<Joint> chain;
  std::vector<std::string> names;
  for (int j = 0; j < 30; ++j) {
    Joint k;
    k.name = "j" + std::to_string(j);
    k.parent = j - 1;
    k.offset = Eigen::Vector3d(0, 1, 0);
    names.push_back(k.name);
    chain.push_back(k);
  }
  auto m = std::make_shared<Motion>();
  m->skeleton = Skeleton::create(std::move(chain)).value();
  m->frame_count = std::size_t{1} << 20;
  m->frame_time = 0.01;
  server::LibraryEntry entry;
  entry.name = "chain";
  entry.source = "chain.bvh";
  entry.motion = m;
  TestServer s({}, {entry});
  const std::uint64_t before = resident_bytes();
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("chain");
  ASSERT_TRUE(v.ok());
  const auto start = std::chrono::steady_clock::now();
  auto edited = c->set_roots(v->id, names);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_FALSE(edited.ok());
  EXPECT_NE(edited.error().message.find("RESOURCE_EXHAUSTED: the edit could write up to 1509949440 bytes (1048576 "
                                        "frames x 180 channels), above the view limit of 67108864 bytes"),
            std::string::npos)
      << edited.error().message;
  const std::uint64_t grown = resident_bytes() - before;
  std::printf("SetRoots of 30 joints on 2^20 channel-less frames: refused in %.3f s, RSS grew %.1f MB\n", seconds,
              static_cast<double>(grown) / 1e6);
  EXPECT_LT(grown, 64u << 20);
  // The view is as it was, and the connection goes on.
  EXPECT_TRUE(c->list_motions().ok());
}

// Before: --max-buffered-bytes was checked before a length prefix, not while
// a body was read: 252 connections each sending a 4 MiB message one byte
// short held 1,031 MB (the server's own gmr_buffered_bytes at 1.06 GB against
// 256 MiB). Now a body is reserved before it is read, from half the budget;
// the rest wait in the kernel.
TEST(Memory, BodiesInFlightAreReservedWithinTheBudgetBeforeTheyAreRead) {
  server::ServerConfig cfg;
  cfg.max_connections_per_address = 0;
  cfg.max_pending_handshakes = 100;
  cfg.max_buffered_bytes = 16u << 20;  // 8 MiB of it for bodies: two 4 MiB messages at a time
  TestServer s(cfg);
  const std::uint32_t length = wire::kDefaultMaxMessageBytes - 1;
  std::string prefix(4, '\0');
  for (int i = 0; i < 4; ++i) prefix[static_cast<std::size_t>(i)] = static_cast<char>(length >> (24 - 8 * i));
  const std::string all_but_one = prefix + std::string(length - 1, 'x');
  constexpr int kSenders = 24;
  std::vector<int> fds;
  std::vector<std::size_t> sent(kSenders, 0);
  for (int i = 0; i < kSenders; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(s.port());
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    (void)::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
    fds.push_back(fd);
  }
  push_for_two_seconds(fds, all_but_one, sent);
  std::size_t whole = 0, total = 0;
  for (auto n : sent) {
    whole += n == all_but_one.size();
    total += n;
  }
  // A well-behaved client is still served meanwhile.
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  EXPECT_TRUE(c->list_motions().ok());
  const auto st = s.server.stats();
  std::printf(
      "%d connections sent %.1f MB of 4 MiB messages (%zu sent all but the last byte): the server held at most "
      "%.1f MB (budget %.1f MB)\n",
      kSenders, static_cast<double>(total) / 1e6, whole, static_cast<double>(st.max_buffered_bytes) / 1e6,
      static_cast<double>(cfg.max_buffered_bytes) / 1e6);
  EXPECT_GT(total, 3u * length) << "the senders pushed more than the budget could hold";
  EXPECT_LE(st.max_buffered_bytes, cfg.max_buffered_bytes) << "bodies in flight stay within the budget";
  for (int fd : fds) ::close(fd);
}

// The WebSocket half: 24 clients upgrade, then each sends a binary message
// announced at 4 MiB - 1 bytes and all of it but the last byte. Read a
// piece at a time and counted as it arrives, the messages in flight stay
// within the budget (before: each was read whole into memory, uncounted
// until complete: 24 x 4 MiB held, the budget never told).
TEST(Memory, WebSocketMessagesInFlightAreCountedAsTheyArrive) {
  server::ServerConfig cfg;
  cfg.http_port = 0;
  cfg.max_connections_per_address = 0;
  cfg.max_buffered_bytes = 16u << 20;
  TestServer s(cfg);
  const std::uint16_t port = s.server.http_port();
  const std::uint64_t length = wire::kDefaultMaxMessageBytes - 1;
  // A masked binary frame (mask key 0: the payload goes as it is), FIN set.
  std::string all_but_one(2 + 8 + 4 + (length - 1), 'x');
  all_but_one[0] = static_cast<char>(0x82);
  all_but_one[1] = static_cast<char>(0x80 | 127);
  for (int i = 0; i < 8; ++i) all_but_one[2 + i] = static_cast<char>((length >> (8 * (7 - i))) & 0xff);
  for (int i = 0; i < 4; ++i) all_but_one[10 + i] = '\0';
  constexpr int kSenders = 24;
  std::vector<int> fds;
  std::vector<std::size_t> sent(kSenders, 0);
  for (int i = 0; i < kSenders; ++i) {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ASSERT_EQ(::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
    const std::string upgrade = "GET /ws HTTP/1.1\r\nHost: 127.0.0.1:" + std::to_string(port) +
                                "\r\nConnection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\n"
                                "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                                "Sec-WebSocket-Protocol: gmr.stream.v1\r\n\r\n";
    ASSERT_EQ(::send(fd, upgrade.data(), upgrade.size(), MSG_NOSIGNAL), static_cast<ssize_t>(upgrade.size()));
    std::string answer;
    char buf[512];
    while (answer.find("\r\n\r\n") == std::string::npos) {
      const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      ASSERT_GT(n, 0) << "no answer to the upgrade";
      answer.append(buf, static_cast<std::size_t>(n));
    }
    ASSERT_EQ(answer.rfind("HTTP/1.1 101", 0), 0u) << answer;
    fds.push_back(fd);
  }
  const std::uint64_t rss_before = resident_bytes();
  push_for_two_seconds(fds, all_but_one, sent);
  std::size_t total = 0;
  for (auto n : sent) total += n;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  EXPECT_TRUE(c->list_motions().ok()) << "a well-behaved client is served meanwhile";
  const auto st = s.server.stats();
  const std::uint64_t grew = resident_bytes() - std::min(resident_bytes(), rss_before);
  std::printf(
      "[ figures  ] %d WebSockets sent %.1f MB of 4 MiB messages: the server counted at most %.1f MB "
      "(budget %.1f MB); the process grew by %.1f MB\n",
      kSenders, static_cast<double>(total) / 1e6, static_cast<double>(st.max_buffered_bytes) / 1e6,
      static_cast<double>(cfg.max_buffered_bytes) / 1e6, static_cast<double>(grew) / 1e6);
  EXPECT_GT(total, 3u * length) << "the senders pushed more than the budget could hold";
  EXPECT_GT(st.max_buffered_bytes, 4u << 20) << "messages in flight are counted as they arrive";
  // The budget, and a piece (64 KiB, grown by the buffer's doubling) per connection past it.
  EXPECT_LE(st.max_buffered_bytes, cfg.max_buffered_bytes + kSenders * (128u << 10));
  // Sanitized builds keep freed memory in quarantine: the figure is reported there only.
  if (!kSlowBuild) {
    EXPECT_LT(grew, 48u << 20) << "messages in flight held outside the budget";
  }
  for (int fd : fds) ::close(fd);
}

}  // namespace
}  // namespace gmr::test
