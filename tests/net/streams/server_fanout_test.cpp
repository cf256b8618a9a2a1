// Fan-out: 1,000 loopback subscribers at once (TCP and UDP, own streams and
// one shared stream), their clients spread over the threads of one shared
// EventLoop. Every frame that arrives must carry exactly the positions `gmr
// positions` computes for its frame index, and sequence numbers that agree
// with its frame indices; TCP must deliver every frame or count it dropped
// (a busy machine drops some: they are counted, never assumed away).
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <condition_variable>
#include <mutex>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/view/view.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

using client::Client;
using client::ReceivedFrame;

// What one subscription saw, checked as frames arrive (on the I/O threads).
struct Seen {
  std::mutex mutex;
  std::uint64_t frames = 0;
  std::uint64_t first_sequence = 0, last_sequence = 0;
  std::int64_t offset = 0;         // frame_index - sequence, modulo the frame count
  std::uint64_t bad_sequence = 0;  // not after the previous one, or a frame index that disagrees with it
  std::uint64_t bad_positions = 0;
  double worst = 0;  // largest position error
  bool udp_mismatch = false;
  std::string first_problem;
  bool ended = false;
  client::SubscriptionEnd end;  // the server's accounting of the subscription
};

struct Ends {
  std::mutex mutex;
  std::condition_variable cv;
  std::size_t ended = 0;
};

// Raises the open-file limit to `need` if the hard limit allows.
bool enough_files(rlim_t need) {
  rlimit r{};
  if (::getrlimit(RLIMIT_NOFILE, &r) != 0) return false;
  if (r.rlim_cur >= need) return true;
  if (r.rlim_max < need) return false;
  r.rlim_cur = need;
  return ::setrlimit(RLIMIT_NOFILE, &r) == 0;
}

TEST(ServerFanout, ThousandSubscribersAcrossThreadsGetExactPositionsAndSequences) {
  // Sanitizer builds run the same test with fewer subscribers: the point
  // there is the memory and UB checks, not the count.
  const std::size_t subscribers = kSlowBuild ? 200 : 1000;
  constexpr std::uint64_t kFrames = 40;
  // Per subscriber: the client's TCP and UDP sockets and the server's TCP one.
  if (!enough_files(static_cast<rlim_t>(subscribers * 3 + 256))) {
    const std::string why = "the open-file limit's hard maximum is below " + std::to_string(subscribers * 3 + 256);
    const char* ci = std::getenv("CI");
    if (ci != nullptr && std::string(ci) == "true") FAIL() << why << " (CI must run this test)";
    GTEST_SKIP() << why;
  }
  const std::string motion = have_data() ? "cmu/02_01" : "walk";
  if (!have_data()) std::fprintf(stderr, "fan-out test: no ../shared/data, using the built-in walk\n");
  std::shared_ptr<const Motion> source;
  for (const auto& e : test_library()) {
    if (e.name == motion) source = e.motion;
  }
  ASSERT_NE(source, nullptr);
  auto view = apply_view(*source, ViewSpec{});
  ASSERT_TRUE(view.ok()) << view.error().to_string();
  const std::vector<Eigen::Vector3d> want = view_positions(*view, 0, view->motion.frame_count);
  const std::size_t joints = view->motion.skeleton.size();
  const auto frame_count = static_cast<std::int64_t>(source->frame_count);
  const double tolerance = 1e-9 * skeleton_size(*source);

  server::ServerConfig cfg;
  cfg.max_connections = subscribers + 16;
  cfg.max_connections_per_address = 0;
  cfg.max_pending_handshakes = subscribers + 16;
  TestServer server(cfg);
  client::ClientOptions options;
  options.loop = std::make_shared<client::EventLoop>(2);

  std::vector<std::unique_ptr<Client>> clients;
  std::vector<std::unique_ptr<Seen>> seen;
  Ends ends;
  for (std::size_t i = 0; i < subscribers; ++i) {
    // Four kinds in turn: TCP own, UDP own, TCP shared, UDP shared.
    const bool udp = i % 2 == 1;
    const bool shared = i % 4 >= 2;
    auto c = server.connect(options);
    ASSERT_NE(c, nullptr) << "client " << i;
    auto v = c->create_view(motion);
    ASSERT_TRUE(v.ok()) << v.error().to_string();
    client::SubscribeOptions so;
    so.loop = true;
    so.udp = udp;
    so.shared = shared;
    so.float64 = true;
    so.max_frames = kFrames;
    so.max_staleness = std::chrono::milliseconds(0);
    seen.push_back(std::make_unique<Seen>());
    Seen* s = seen.back().get();
    auto on_frame = [s, udp, &want, joints, frame_count, tolerance](const ReceivedFrame& f) {
      std::lock_guard lock(s->mutex);
      auto problem = [&](const std::string& what) {
        if (s->first_problem.empty()) s->first_problem = what;
      };
      if (f.udp != udp) s->udp_mismatch = true;
      const auto index = static_cast<std::int64_t>(f.frame_index);
      const std::int64_t offset =
          ((index - static_cast<std::int64_t>(f.sequence)) % frame_count + frame_count) % frame_count;
      if (s->frames == 0) {
        s->first_sequence = f.sequence;
        s->offset = offset;
      } else if (f.sequence <= s->last_sequence || offset != s->offset) {
        ++s->bad_sequence;
        problem("sequence " + std::to_string(f.sequence) + " (frame " + std::to_string(index) + ") after " +
                std::to_string(s->last_sequence));
      }
      s->last_sequence = f.sequence;
      ++s->frames;
      if (index >= frame_count || f.positions.size() != joints) {
        ++s->bad_positions;
        problem("frame " + std::to_string(index) + " with " + std::to_string(f.positions.size()) + " positions");
        return;
      }
      double worst = 0;
      for (std::size_t j = 0; j < joints; ++j) {
        worst = std::max(worst, (f.positions[j] - want[static_cast<std::size_t>(index) * joints + j]).norm());
      }
      s->worst = std::max(s->worst, worst);
      if (!(worst <= tolerance)) {
        ++s->bad_positions;
        problem("frame " + std::to_string(index) + " off by " + std::to_string(worst));
      }
    };
    auto on_end = [&ends, s](const client::SubscriptionEnd& e) {
      {
        std::lock_guard lock(s->mutex);
        s->ended = true;
        s->end = e;
      }
      std::lock_guard lock(ends.mutex);
      ++ends.ended;
      ends.cv.notify_all();
    };
    auto sub = c->subscribe(v->id, so, on_frame, on_end);
    ASSERT_TRUE(sub.ok()) << "subscriber " << i << ": " << sub.error().to_string();
    clients.push_back(std::move(c));
  }
  {
    std::unique_lock lock(ends.mutex);
    ends.cv.wait_for(lock, std::chrono::seconds(60), [&] { return ends.ended == subscribers; });
    ASSERT_EQ(ends.ended, subscribers) << "subscriptions that never ended";
  }
  // A UDP frame may still be on its way after the end arrived over TCP.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));

  std::uint64_t tcp_frames = 0, udp_frames = 0, udp_due = 0, dropped = 0, skipped = 0;
  std::size_t checked = 0;
  for (std::size_t i = 0; i < subscribers; ++i) {
    Seen& s = *seen[i];
    std::lock_guard lock(s.mutex);
    const bool udp = i % 2 == 1;
    SCOPED_TRACE("subscriber " + std::to_string(i) + (udp ? " (UDP)" : " (TCP)"));
    EXPECT_EQ(s.bad_sequence, 0u) << s.first_problem;
    EXPECT_EQ(s.bad_positions, 0u) << s.first_problem << " (worst " << s.worst << ")";
    EXPECT_FALSE(s.udp_mismatch);
    EXPECT_LE(s.frames, kFrames);
    if (s.frames > 0) {
      EXPECT_LT(s.last_sequence - s.first_sequence, kFrames);
    }
    (udp ? udp_frames : tcp_frames) += s.frames;
    checked += s.frames;
    // The server counts every one of the max_frames ticks against the
    // subscription; of those it names the frames it gave up (dropped for a
    // slow or stale client, skipped when it fell behind).
    ASSERT_TRUE(s.ended);
    EXPECT_EQ(s.end.frames_sent, kFrames);
    const std::uint64_t gone = s.end.frames_dropped + s.end.frames_skipped;
    EXPECT_LE(gone, kFrames);
    dropped += s.end.frames_dropped;
    skipped += s.end.frames_skipped;
    if (udp) {
      // Loopback may lose a datagram beyond what the server counted.
      EXPECT_LE(s.frames + gone, kFrames);
      udp_due += kFrames - std::min<std::uint64_t>(gone, kFrames);
    } else {
      // TCP: every frame not given up arrived.
      EXPECT_EQ(s.frames + gone, kFrames);
    }
  }
  // UDP: nearly all the frames the server sent arrive.
  EXPECT_GE(udp_frames * 10, udp_due * (kSlowBuild ? 5 : 9));
  std::fprintf(stderr, "fan-out test: %llu frames dropped and %llu skipped by the server\n",
               static_cast<unsigned long long>(dropped), static_cast<unsigned long long>(skipped));
  std::fprintf(stderr,
               "fan-out test: %zu subscribers, %zu frames checked (%llu over TCP, %llu over UDP of %llu sent)\n",
               subscribers, checked, static_cast<unsigned long long>(tcp_frames),
               static_cast<unsigned long long>(udp_frames), static_cast<unsigned long long>(udp_due));
  EXPECT_GT(checked, 0u);
}

}  // namespace
}  // namespace gmr::test
