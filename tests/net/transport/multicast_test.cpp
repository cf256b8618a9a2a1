// Multicast: subscribers of a shared stream over TRANSPORT_MULTICAST all get
// its frames, with the positions `gmr positions` gives, from one send per
// frame to the group. Multicast datagrams are not loopback traffic: the test
// runs itself again inside a network namespace it makes (`unshare -n`, the
// loopback interface up, a multicast route on it), so nothing can leave the
// machine. Where a namespace cannot be made it skips, and fails under CI=true.
#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>
#include <sys/wait.h>

#include <sstream>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/view/view.h"
#include "net_test_util.h"
#include "recording_outbox.h"
#include "server_parts.h"
#include "test_data.h"

namespace gmr::test {
namespace {

bool in_namespace() {
  const char* v = std::getenv("GMR_IN_NETNS");
  return v != nullptr && std::string(v) == "1";
}

// Runs this test binary's `test` again in a new network namespace; its
// output, and whether it passed.
// `multicast_route`: 224.0.0.0/4 routed on the loopback interface (as a
// LAN interface would carry it); without it the group is routed nowhere.
void run_in_namespace(const std::string& test, bool multicast_route = true) {
  const bool ci = std::getenv("CI") != nullptr && std::string(std::getenv("CI")) == "true";
  if (std::system("unshare -n true >/dev/null 2>&1") != 0) {
    const std::string why = "cannot make a network namespace here (unshare -n needs root or CAP_SYS_ADMIN)";
    if (ci) FAIL() << why << ": CI must run the multicast test";
    GTEST_SKIP() << why;
  }
  const std::string cmd = std::string("unshare -n sh -c 'ip link set lo up && ") +
                          (multicast_route ? "ip route add 224.0.0.0/4 dev lo && " : "") +
                          "GMR_IN_NETNS=1 exec /proc/" + std::to_string(::getpid()) + "/exe --gtest_filter=" + test +
                          "' 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  std::array<char, 4096> buf{};
  for (std::size_t n; (n = std::fread(buf.data(), 1, buf.size(), p)) > 0;) out.append(buf.data(), n);
  const int status = ::pclose(p);
  std::fprintf(stderr, "%s", out.c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "in the namespace:\n" << out;
  EXPECT_NE(out.find("[  PASSED  ] 1 test"), std::string::npos) << out;
}

struct Received {
  std::mutex mutex;
  std::size_t frames = 0, bad = 0;
  double worst = 0;
  Latch<client::SubscriptionEnd> end;
};

TEST(Multicast, OneSendPerFrameReachesEverySubscriberWithExactPositions) {
  if (!in_namespace()) return run_in_namespace("Multicast.OneSendPerFrameReachesEverySubscriberWithExactPositions");

  const std::string motion = have_data() ? "cmu/02_01" : "walk";
  std::shared_ptr<const Motion> source;
  for (const auto& e : test_library()) {
    if (e.name == motion) source = e.motion;
  }
  ASSERT_NE(source, nullptr);
  auto view = apply_view(*source, ViewSpec{});
  ASSERT_TRUE(view.ok());
  const std::vector<Eigen::Vector3d> want = view_positions(*view, 0, view->motion.frame_count);
  const std::size_t joints = view->motion.skeleton.size();
  const double tolerance = 1e-9 * skeleton_size(*source);

  server::ServerConfig cfg;
  cfg.multicast_group = "239.255.74.1";
  cfg.multicast_port = 17500;
  TestServer s(cfg);
  constexpr std::uint64_t kFrames = 60;
  constexpr int kSubscribers = 3;
  std::vector<std::unique_ptr<client::Client>> clients;
  std::vector<std::unique_ptr<Received>> got;
  std::uint64_t stream_id = 0;
  for (int i = 0; i < kSubscribers; ++i) {
    clients.push_back(s.connect());
    ASSERT_NE(clients.back(), nullptr);
    auto v = clients.back()->create_view(motion);
    ASSERT_TRUE(v.ok());
    got.push_back(std::make_unique<Received>());
    Received* r = got.back().get();
    client::SubscribeOptions so;
    so.multicast = true;
    so.float64 = true;
    so.loop = true;
    so.rate_hz = kSlowBuild ? 60 : 120;
    so.max_frames = kFrames;
    so.max_staleness = std::chrono::milliseconds(0);
    auto sub = clients.back()->subscribe(
        v->id, so,
        [r, &want, joints, tolerance](const client::ReceivedFrame& f) {
          std::lock_guard lock(r->mutex);
          ++r->frames;
          if (!f.udp || f.positions.size() != joints) {
            ++r->bad;
            return;
          }
          for (std::size_t j = 0; j < joints; ++j) {
            const double e = (f.positions[j] - want[f.frame_index * joints + j]).norm();
            r->worst = std::max(r->worst, e);
            if (!(e <= tolerance)) ++r->bad;
          }
        },
        [r](const client::SubscriptionEnd& e) { r->end.set(e); });
    ASSERT_TRUE(sub.ok()) << sub.error().to_string();
    EXPECT_EQ(sub->multicast_group, "239.255.74.1:17500");
    if (i == 0) stream_id = sub->stream_id;
    EXPECT_EQ(sub->stream_id, stream_id) << "multicast subscribers share one stream";
  }
  for (int i = 0; i < kSubscribers; ++i) {
    Received& r = *got[static_cast<std::size_t>(i)];
    ASSERT_TRUE(r.end.wait().has_value());
    std::lock_guard lock(r.mutex);
    EXPECT_EQ(r.bad, 0u);
    // The later subscribers joined a running stream: they end with it.
    EXPECT_GE(r.frames, kFrames * 8 / 10 - 10) << "subscriber " << i;
    std::fprintf(stderr, "multicast subscriber %d: %zu frames, worst %.3g\n", i, r.frames, r.worst);
  }
  const auto stats = clients[0]->stats();
  ASSERT_TRUE(stats.ok());
  // One datagram train per frame for all three subscribers, not three (the
  // stream runs on until the last to join has had its kFrames).
  EXPECT_LT(stats->multicast_frames_sent, 2 * kFrames);
  EXPECT_GE(stats->multicast_frames_sent, kFrames * 8 / 10);
  std::fprintf(stderr, "multicast: %llu frames sent for %d subscribers\n",
               static_cast<unsigned long long>(stats->multicast_frames_sent), kSubscribers);

  // Multicast follows its shared stream: it cannot pause on its own.
  auto v = clients[0]->create_view(motion);
  client::SubscribeOptions so;
  so.multicast = true;
  so.loop = true;
  auto sub = clients[0]->subscribe(v->id, so, [](const client::ReceivedFrame&) {});
  ASSERT_TRUE(sub.ok());
  const auto paused = clients[0]->pause(sub->id);
  ASSERT_FALSE(paused.ok());
  EXPECT_NE(paused.error().message.find("multicast"), std::string::npos);
  // Nor start paused.
  so.paused = true;
  const auto held = clients[0]->subscribe(v->id, so, [](const client::ReceivedFrame&) {});
  ASSERT_FALSE(held.ok());
  EXPECT_NE(held.error().message.find("cannot start paused"), std::string::npos) << held.error().message;
}

// However many subscribers a shared stream has over multicast, they are one
// target of it, their channel: a tick sends once and touches none of them
// (before, each was a target visited every frame: 10,000 cost a quarter of a
// core). Each still ends on its own max_frames with its own counts, one that
// unsubscribes leaves at once, one whose session went is forgotten within
// the channel's sweep, and the channel leaves the stream with its last member.
TEST(Multicast, SubscribersAreOneTargetOfTheirStreamAndEachEndsOnItsOwnCount) {
  if (!in_namespace()) {
    return run_in_namespace("Multicast.SubscribersAreOneTargetOfTheirStreamAndEachEndsOnItsOwnCount");
  }
  spdlog::set_level(spdlog::level::warn);
  server::ServerConfig cfg;
  cfg.multicast_group = "239.255.74.1";
  cfg.multicast_port = 17502;
  cfg.send_budget = 0;
  ServerParts parts(cfg, test_library());
  parts.udp.open(server::net::ip::make_address("127.0.0.1"), 0);
  parts.multicast.group = parts.udp.open_multicast(cfg.multicast_group, cfg.multicast_port, 1);
  parts.udp.start();
#ifdef GMR_SANITIZED
  constexpr int kSubscribers = 400;
#else
  constexpr int kSubscribers = 4000;
#endif
  std::vector<RecordedSession> sessions;
  std::uint64_t stream_id = 0;
  for (int i = 0; i < kSubscribers; ++i) {
    RecordedSession s(parts.services, static_cast<std::uint64_t>(i + 1));
    s.max_frames = i % 4 == 0 ? 10 + static_cast<std::uint64_t>(i % 13) : 0;
    const std::uint32_t view = s.create_view("walk");
    ASSERT_NE(view, 0u);
    pb::ClientMessage sub;
    sub.mutable_subscribe()->set_view_id(view);
    sub.mutable_subscribe()->set_transport(pb::TRANSPORT_MULTICAST);
    sub.mutable_subscribe()->set_rate_hz(500);
    sub.mutable_subscribe()->set_loop(true);
    sub.mutable_subscribe()->set_max_frames(s.max_frames);
    const auto r = s.ask(sub);
    ASSERT_TRUE(r.has_subscribed()) << r.DebugString();
    if (i == 0) stream_id = r.subscribed().stream_id();
    ASSERT_EQ(r.subscribed().stream_id(), stream_id);
    sessions.push_back(std::move(s));
  }
  const auto stream = parts.streams.find(stream_id);
  ASSERT_NE(stream, nullptr);
  EXPECT_EQ(stream->target_count(), 1u) << "the channel is the stream's one target for " << kSubscribers;
  const auto channel = parts.multicast.channels.at(stream_id).lock();
  ASSERT_NE(channel, nullptr);
  EXPECT_EQ(channel->members(), static_cast<std::size_t>(kSubscribers));
  // Admission counts each its share of the one send (issue 39: before, each counted as an own stream).
  EXPECT_DOUBLE_EQ(parts.admission.committed_frames_per_second(),
                   kSubscribers * 500 * server::Admission::send_cost(server::Admission::SendKind::kMulticast));

  // Every member with a max_frames ends on it (the longest is 22 frames).
  for (int round = 0; round < 200 && parts.multicast.frames_sent + channel->dropped() < 30; ++round) {
    parts.io.run_for(std::chrono::milliseconds(20));
  }
  std::size_t ended = 0;
  for (const RecordedSession& s : sessions) {
    const auto e = s.ended();
    if (s.max_frames == 0) {
      EXPECT_FALSE(e.has_value()) << "no max_frames: it goes on";
      continue;
    }
    ASSERT_TRUE(e.has_value()) << "a member with max_frames " << s.max_frames << " did not end";
    EXPECT_EQ(e->frames_sent(), s.max_frames);
    EXPECT_EQ(e->reason(), "max_frames reached");
    ++ended;
  }
  EXPECT_EQ(ended, static_cast<std::size_t>(kSubscribers / 4));
  EXPECT_EQ(channel->members(), static_cast<std::size_t>(kSubscribers - kSubscribers / 4));
  EXPECT_GE(channel->sent(), 22u) << "frames go to the group (dropped " << channel->dropped() << ")";
  EXPECT_EQ(stream->target_count(), 1u);

  // Half of the others unsubscribe: they leave at once.
  std::size_t left = 0;
  for (std::size_t i = 1; i < sessions.size(); i += 4) {
    pb::ClientMessage un;
    un.mutable_unsubscribe()->set_subscription_id(1);
    ASSERT_FALSE(sessions[i].ask(un).has_error());
    ++left;
  }
  const std::size_t members = static_cast<std::size_t>(kSubscribers - kSubscribers / 4) - left;
  EXPECT_EQ(channel->members(), members);
  // Others' sessions end without a word (as a dropped connection's handler
  // goes): they are forgotten by the next sweep.
  std::size_t gone = 0;
  for (std::size_t i = 2; i < sessions.size(); i += 4) {
    sessions[i].handler.reset();
    ++gone;
  }
  const auto sweep_by = server::Clock::now() + server::MulticastChannel::kSweepEvery + std::chrono::milliseconds(500);
  while (channel->members() == members && server::Clock::now() < sweep_by) {
    parts.io.run_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(channel->members(), members - gone);
  EXPECT_EQ(stream->target_count(), 1u);

  // The last ones leave: so does the channel, and the stream is idle.
  for (std::size_t i = 3; i < sessions.size(); i += 4) {
    pb::ClientMessage un;
    un.mutable_unsubscribe()->set_subscription_id(1);
    ASSERT_FALSE(sessions[i].ask(un).has_error());
  }
  EXPECT_EQ(channel->members(), 0u);
  EXPECT_TRUE(stream->idle());
  std::fprintf(stderr, "multicast: %d subscribers, one target; %llu frames sent, %llu dropped\n", kSubscribers,
               static_cast<unsigned long long>(channel->sent()), static_cast<unsigned long long>(channel->dropped()));
  for (auto& s : sessions) {
    if (s.handler) s.handler->on_stop();
  }
}

#ifdef GMR_CLI_PATH
TEST(Multicast, GmrDiscoverListsTheServersThatSendBeacons) {
  if (!in_namespace()) return run_in_namespace("Multicast.GmrDiscoverListsTheServersThatSendBeacons");
  server::ServerConfig cfg;
  cfg.discovery_group = "239.255.74.2";
  cfg.discovery_port = 17501;
  cfg.discovery_interval = std::chrono::milliseconds(200);
  cfg.server_name = "stage-left";
  cfg.multicast_group = "239.255.74.1";
  cfg.multicast_port = 17500;
  TestServer a(cfg);
  cfg.server_name = "stage-right";
  cfg.multicast_group.clear();
  TestServer b(cfg);
  TestServer silent;  // no --discovery-group: never listed
  const CommandRun heard = run_command(std::string(GMR_CLI_PATH) + " discover --port 17501 --seconds 1");
  const std::string& out = heard.out;
  ASSERT_EQ(heard.status, 0) << out;
  std::fprintf(stderr, "%s", out.c_str());
  for (const auto* s : {&a, &b}) {
    const std::string where = "127.0.0.1:" + std::to_string(s->port());
    const auto line = out.find(where);
    ASSERT_NE(line, std::string::npos) << out;
    const std::string row = out.substr(line, out.find('\n', line) - line);
    EXPECT_NE(row.find(s == &a ? "stage-left" : "stage-right"), std::string::npos) << row;
    EXPECT_NE(row.find(std::to_string(s->server.udp_port())), std::string::npos) << row;
    if (s == &a) {
      EXPECT_NE(row.find("multicast 239.255.74.1:17500"), std::string::npos) << row;
    }
  }
  EXPECT_EQ(out.find("127.0.0.1:" + std::to_string(silent.port())), std::string::npos) << out;
  EXPECT_NE(out.find("2 servers heard on 239.255.74.2:17501"), std::string::npos) << out;

  // Nobody on another port: gmr discover says where the group is routed and
  // what a server must bind to be heard.
  const CommandRun none = run_command(std::string(GMR_CLI_PATH) + " discover --port 17599 --seconds 0.3");
  ASSERT_EQ(none.status, 0) << none.out;
  EXPECT_NE(none.out.find("0 servers heard"), std::string::npos) << none.out;
  EXPECT_NE(none.out.find("heard nothing: this machine routes 239.255.74.2 on an interface with no address of its own"),
            std::string::npos)
      << none.out;
  EXPECT_NE(none.out.find("--bind"), std::string::npos) << none.out;

  // Before: `gmr stream --multicast --summary` said it streamed "over TCP".
  const CommandRun stream = run_command(
      std::string(GMR_CLI_PATH) + " stream walk --multicast --summary --count 3 --port " + std::to_string(a.port()));
  ASSERT_EQ(stream.status, 0) << stream.out;
  EXPECT_NE(stream.out.find("streaming walk over multicast"), std::string::npos) << stream.out;
}
#endif

// Before: a server bound to 127.0.0.1 (the default) with --discovery-group
// logged that beacons went out, and nobody heard them, with no word why.
// Where the group is not routed on loopback, the server now says so at start,
// for beacons and for the multicast group; where it is, it says nothing.
std::string start_log(bool expect_warning) {
  std::ostringstream log;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  const auto previous = spdlog::default_logger();
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("capture", sink));
  {
    server::ServerConfig cfg;
    cfg.discovery_group = "239.255.74.2";
    cfg.discovery_port = 17503;
    cfg.multicast_group = "239.255.74.1";
    cfg.multicast_port = 17504;
    TestServer s(cfg);
    EXPECT_NE(s.port(), 0);
  }
  spdlog::set_default_logger(previous);
  const std::string text = log.str();
  for (const char* what : {"discovery beacons will reach no one: bound to 127.0.0.1",
                           "multicast streams will reach no one: bound to 127.0.0.1"}) {
    EXPECT_EQ(text.find(what) != std::string::npos, expect_warning) << what << " in:\n" << text;
  }
  return text;
}

TEST(Multicast, ALoopbackServerSaysWhenNobodyCanHearIt) {
  if (!in_namespace()) return run_in_namespace("Multicast.ALoopbackServerSaysWhenNobodyCanHearIt", false);
  const std::string text = start_log(true);
  EXPECT_NE(text.find("routes 239.255.74.2 nowhere"), std::string::npos) << text;
  EXPECT_NE(text.find("--bind"), std::string::npos) << text;
}

TEST(Multicast, ALoopbackServerIsQuietWhereLoopbackCarriesTheGroup) {
  if (!in_namespace()) return run_in_namespace("Multicast.ALoopbackServerIsQuietWhereLoopbackCarriesTheGroup");
  start_log(false);
}

TEST(Multicast, AServerWithoutAGroupRefusesMulticast) {
  TestServer s;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("walk");
  ASSERT_TRUE(v.ok());
  client::SubscribeOptions so;
  so.multicast = true;
  const auto sub = c->subscribe(v->id, so, [](const client::ReceivedFrame&) {});
  ASSERT_FALSE(sub.ok());
  EXPECT_NE(sub.error().message.find("FAILED_PRECONDITION: this server sends no multicast"), std::string::npos)
      << sub.error().message;
}

}  // namespace
}  // namespace gmr::test
