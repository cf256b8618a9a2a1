// The server's I/O threads (server/src/io_threads.h): connections spread
// over them, the least busy first; every thread's clients get exact frames
// over TCP and UDP; pipelined requests are answered in order whichever thread
// reads them; one thread runs everything on the control loop.
#include <gtest/gtest.h>
#include <sched.h>

#include <map>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/view/view.h"
#include "gmr/wire/framing.h"
#include "transport/io_threads.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

// How many of the server's TCP connections run on each I/O thread.
std::map<std::size_t, std::size_t> per_thread(const server::ServerStats& st) {
  std::map<std::size_t, std::size_t> n;
  for (const auto& s : st.sessions) ++n[s.io_thread];
  return n;
}

TEST(IoThreads, ZeroMeansOnePerCpuThisProcessMayRunOn) {
  cpu_set_t set;
  CPU_ZERO(&set);
  ASSERT_EQ(::sched_getaffinity(0, sizeof set, &set), 0);
  const auto cpus = static_cast<std::size_t>(CPU_COUNT(&set));
  EXPECT_EQ(server::io_thread_count(0), std::min(cpus, server::kMaxIoThreads));
  EXPECT_EQ(server::io_thread_count(3), 3u);
  EXPECT_EQ(server::io_thread_count(1000), server::kMaxIoThreads);
}

TEST(IoThreads, TwoThreadsShareTheConnections) {
  server::ServerConfig cfg;
  cfg.io_threads = 2;
  TestServer s(cfg);
  std::vector<std::unique_ptr<client::Client>> clients;
  for (int i = 0; i < 5; ++i) {
    clients.push_back(s.connect());
    ASSERT_NE(clients.back(), nullptr);
  }
  EXPECT_EQ(per_thread(s.server.stats()), (std::map<std::size_t, std::size_t>{{0, 3}, {1, 2}}));
}

// From three threads on, the control loop's thread keeps to the control
// loop: connections go to the others, the least busy first.
TEST(IoThreads, ConnectionsGoToTheLeastBusyThread) {
  server::ServerConfig cfg;
  cfg.io_threads = 4;
  TestServer s(cfg);
  std::vector<std::unique_ptr<client::Client>> clients;
  for (int i = 0; i < 6; ++i) {
    clients.push_back(s.connect());
    ASSERT_NE(clients.back(), nullptr);
  }
  auto st = s.server.stats();
  EXPECT_EQ(st.io_threads, 4u);
  EXPECT_EQ(per_thread(st), (std::map<std::size_t, std::size_t>{{1, 2}, {2, 2}, {3, 2}}));
  // A client reads its own thread from GetStats, as the server counts it.
  std::map<std::uint64_t, std::size_t> by_id;
  for (const auto& session : st.sessions) by_id[session.id] = session.io_thread;
  std::size_t on_two = 0;
  for (auto& c : clients) {
    auto own = c->stats();
    ASSERT_TRUE(own.ok()) << own.error().to_string();
    EXPECT_EQ(own->io_threads, 4u);
    if (own->io_thread == 2) ++on_two;
  }
  EXPECT_EQ(on_two, 2u);
  // Two clients of thread 2 leave: the next two connections go there.
  std::size_t closed = 0;
  for (auto& c : clients) {
    if (closed < 2 && c->stats()->io_thread == 2) {
      c->close();
      c.reset();
      ++closed;
    }
  }
  for (int i = 0; i < 200 && s.server.stats().connections != 4; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(s.server.stats().connections, 4u);
  for (int i = 0; i < 2; ++i) {
    auto c = s.connect();
    ASSERT_NE(c, nullptr);
    EXPECT_EQ(c->stats()->io_thread, 2u);
    clients.push_back(std::move(c));
  }
  EXPECT_EQ(per_thread(s.server.stats()), (std::map<std::size_t, std::size_t>{{1, 2}, {2, 2}, {3, 2}}));
}

TEST(IoThreads, OneThreadRunsEverythingOnTheControlLoop) {
  server::ServerConfig cfg;
  cfg.io_threads = 1;
  TestServer s(cfg);
  auto a = s.connect();
  auto b = s.connect();
  ASSERT_TRUE(a && b);
  const auto st = s.server.stats();
  EXPECT_EQ(st.io_threads, 1u);
  EXPECT_EQ(per_thread(st), (std::map<std::size_t, std::size_t>{{0, 2}}));
  // And it streams.
  auto v = a->create_view("walk");
  ASSERT_TRUE(v.ok()) << v.error().to_string();
  std::uint64_t dropped = 0;
  const auto frames = stream_all(*a, *v, /*udp=*/false, /*float64=*/true, /*orientations=*/false, 2000.0, &dropped);
  expect_delivered_or_counted(frames.size(), dropped, v->frame_count);
}

// Requests sent in one burst to a connection on the control loop's thread
// and on another: every one answered, in order (a connection hands one at a
// time to the control loop and reads the next after its answer).
TEST(IoThreads, PipelinedRequestsAreAnsweredInOrderOnEveryThread) {
  server::ServerConfig cfg;
  cfg.io_threads = 2;
  TestServer s(cfg);
  std::vector<std::unique_ptr<RawConnection>> raw;
  for (int t = 0; t < 4; ++t) {
    raw.push_back(std::make_unique<RawConnection>(s.port()));
    raw.back()->handshake();
  }
  EXPECT_EQ(per_thread(s.server.stats()), (std::map<std::size_t, std::size_t>{{0, 2}, {1, 2}}));
  for (auto& c : raw) {
    std::string burst;
    for (std::uint64_t id = 100; id < 400; ++id) {
      pb::ClientMessage m = request(id);
      if (id % 3 == 0) {
        m.mutable_list_motions();
      } else if (id % 3 == 1) {
        m.mutable_create_view()->set_motion("walk");
      } else {
        m.mutable_get_stats();
      }
      burst += wire::frame_message(m).value();
    }
    c->send_bytes(burst);
  }
  for (auto& c : raw) {
    for (std::uint64_t id = 100; id < 400; ++id) {
      auto reply = c->reply();
      ASSERT_TRUE(reply.has_value()) << "reply to " << id;
      ASSERT_EQ(reply->request_id(), id);
      if (id % 3 == 1) {
        // Past max_views_per_connection views are refused; either way it is this request's answer.
        EXPECT_TRUE(reply->has_view() || reply->has_error());
      }
    }
  }
}

// Clients on every thread but the control loop's, each with a TCP and a UDP
// subscription of its own and one TCP subscription of a shared stream: every
// frame exact, every sequence number in order.
TEST(IoThreads, EveryThreadsClientsGetExactFramesOverTcpAndUdp) {
  server::ServerConfig cfg;
  cfg.io_threads = 3;
  TestServer s(cfg);
  const std::string motion = have_data() ? "cmu/02_01" : "walk";
  std::shared_ptr<const Motion> source;
  for (const auto& e : test_library()) {
    if (e.name == motion) source = e.motion;
  }
  ASSERT_NE(source, nullptr);
  auto view = apply_view(*source, ViewSpec{});
  ASSERT_TRUE(view.ok());
  const auto want = view_positions(*view, 0, view->motion.frame_count);
  const std::size_t joints = view->motion.skeleton.size();
  const double tolerance = 1e-9 * skeleton_size(*source);

  std::vector<std::unique_ptr<client::Client>> clients;
  for (int i = 0; i < 6; ++i) {
    clients.push_back(s.connect());
    ASSERT_NE(clients.back(), nullptr);
  }
  EXPECT_EQ(per_thread(s.server.stats()), (std::map<std::size_t, std::size_t>{{1, 3}, {2, 3}}));

  constexpr std::uint64_t kFrames = 60;
  struct Got {
    std::mutex m;
    std::vector<client::ReceivedFrame> frames;
    Latch<client::SubscriptionEnd> end;
  };
  std::vector<std::unique_ptr<Got>> got;
  for (auto& c : clients) {
    auto v = c->create_view(motion);
    ASSERT_TRUE(v.ok()) << v.error().to_string();
    for (int kind = 0; kind < 3; ++kind) {
      client::SubscribeOptions o;
      o.udp = kind == 1;
      o.shared = kind == 2;
      o.float64 = true;
      o.rate_hz = 600;
      o.max_frames = kFrames;
      o.max_staleness = std::chrono::milliseconds(0);
      got.push_back(std::make_unique<Got>());
      Got* g = got.back().get();
      auto sub = c->subscribe(
          v->id, o,
          [g](const client::ReceivedFrame& f) {
            std::lock_guard lock(g->m);
            g->frames.push_back(f);
          },
          [g](const client::SubscriptionEnd& e) { g->end.set(e); });
      ASSERT_TRUE(sub.ok()) << sub.error().to_string();
    }
  }
  std::size_t checked = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    Got& g = *got[i];
    const bool udp = i % 3 == 1;
    SCOPED_TRACE("client " + std::to_string(i / 3) + (udp ? " UDP" : i % 3 == 2 ? " shared TCP" : " TCP"));
    const auto end = g.end.wait();
    ASSERT_TRUE(end.has_value()) << "the subscription never ended";
    if (udp) std::this_thread::sleep_for(std::chrono::milliseconds(50));  // the last datagrams
    std::lock_guard lock(g.m);
    // TCP: every frame arrived, or the server counted it dropped.
    if (!udp) {
      EXPECT_EQ(g.frames.size() + end->frames_dropped, kFrames)
          << "sent " << end->frames_sent << ", dropped " << end->frames_dropped;
    } else {
      EXPECT_GE(g.frames.size() * 10, kFrames * (kSlowBuild ? 5 : 9));
    }
    for (std::size_t k = 0; k < g.frames.size(); ++k) {
      const auto& f = g.frames[k];
      if (k > 0) {
        ASSERT_GT(f.sequence, g.frames[k - 1].sequence);
      }
      ASSERT_EQ(f.positions.size(), joints);
      ASSERT_LT(f.frame_index, view->motion.frame_count);
      for (std::size_t j = 0; j < joints; ++j) {
        ASSERT_LE((f.positions[j] - want[f.frame_index * joints + j]).norm(), tolerance)
            << "frame " << f.frame_index << " joint " << j;
      }
      ++checked;
    }
  }
  EXPECT_GT(checked, 6 * kFrames * 2);
}

}  // namespace
}  // namespace gmr::test
