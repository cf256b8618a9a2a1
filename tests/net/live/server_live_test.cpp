// Live sources: a client with a 'publish' token announces a real motion's
// skeleton and pushes its frames; subscribers with a world view, a re-rooted
// view, an intrinsic view and a shared stream receive exactly the positions
// `gmr positions` computes for the same frames and options. A source that
// ends or disconnects ends its subscribers; bad skeletons and bad frames get
// errors and never reach a subscriber.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <map>
#include <thread>

#include <nats/nats.h>

#include "gmr/io/motion_file.h"
#include "gmr/relay/v1/relay.pb.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/server/library.h"
#include "gmr/server/auth.h"
#include "gmr/view/view.h"
#include "gmr/ops/convert.h"
#include "gmr/retarget/retarget.h"
#include "gmr/wire/convert.h"
#include "live_test_util.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

using client::Client;
using client::ReceivedFrame;

// The real motion the tests publish: CMU 02_01 with the corpus, else the
// built-in walk.
std::shared_ptr<const Motion> source_motion() {
  const std::string name = have_data() ? "cmu/02_01" : "walk";
  if (!have_data()) std::fprintf(stderr, "live test: no ../shared/data, publishing the built-in walk\n");
  for (const auto& e : test_library()) {
    if (e.name == name) return e.motion;
  }
  return nullptr;
}

// Positions `gmr positions` gives frame f of `source` with `spec`, by joint name.
struct Reference {
  std::vector<std::map<std::string, Eigen::Vector3d>> frames;
};
Reference reference(const Motion& source, const ViewSpec& spec, std::size_t frames) {
  Reference r;
  auto view = apply_view(source, spec);
  EXPECT_TRUE(view.ok()) << view.error().to_string();
  if (!view.ok()) return r;
  const auto rows = view_positions(*view, 0, frames);
  const Skeleton names = view_names(*view);
  r.frames.resize(frames);
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t k = 0; k < names.size(); ++k) {
      r.frames[f][names.joint(static_cast<int>(k)).name] = rows[f * names.size() + k];
    }
  }
  return r;
}

// What one subscription received, checked against its reference as it arrives.
struct Watch {
  std::mutex mutex;
  Skeleton skeleton;
  std::vector<int> joints;
  const Reference* want = nullptr;
  double tolerance = 0;
  std::vector<std::uint64_t> indices, sequences;
  std::size_t compared = 0, bad = 0;
  double worst = 0;
  std::string first_problem;
  Latch<client::SubscriptionEnd> end;

  void on_frame(const ReceivedFrame& f) {
    std::lock_guard lock(mutex);
    indices.push_back(f.frame_index);
    sequences.push_back(f.sequence);
    if (f.frame_index >= want->frames.size() || f.positions.size() != joints.size()) {
      ++bad;
      if (first_problem.empty()) first_problem = "frame " + std::to_string(f.frame_index) + " is not one published";
      return;
    }
    const auto& ref = want->frames[f.frame_index];
    for (std::size_t i = 0; i < joints.size(); ++i) {
      const std::string& name = skeleton.joint(joints[i]).name;
      const auto it = ref.find(name);
      if (it == ref.end()) continue;
      const double e = (f.positions[i] - it->second).norm();
      worst = std::max(worst, e);
      ++compared;
      if (!(e <= tolerance)) {
        ++bad;
        if (first_problem.empty()) {
          first_problem = "frame " + std::to_string(f.frame_index) + ", " + name + ": off by " + std::to_string(e);
        }
      }
    }
  }
};

// Subscribes `w` to every joint of view `view` of `c`.
client::SubscriptionInfo watch(Client& c, const client::ViewState& view, client::SubscribeOptions so, Watch& w) {
  so.max_staleness = std::chrono::milliseconds(0);
  {
    // A late subscriber's first frame may come before the reply is read
    // here: its joints are the view's, all of them.
    std::lock_guard lock(w.mutex);
    w.skeleton = view.skeleton;
    w.joints.clear();
    for (int j = 0; j < static_cast<int>(view.skeleton.size()); ++j) w.joints.push_back(j);
  }
  auto sub = c.subscribe(
      view.id, so, [&w](const ReceivedFrame& f) { w.on_frame(f); },
      [&w](const client::SubscriptionEnd& e) { w.end.set(e); },
      [&w](const client::SkeletonChange& change) {
        std::lock_guard lock(w.mutex);
        w.skeleton = change.skeleton;
        w.joints = change.joints;
      });
  EXPECT_TRUE(sub.ok()) << sub.error().to_string();
  if (!sub.ok()) return {};
  std::lock_guard lock(w.mutex);
  w.skeleton = sub->skeleton;
  w.joints = sub->joints;
  return *sub;
}

// Pushes frames [begin, end) of `m`, one per `period`.
void publish_frames(Client& c, std::uint32_t id, const Motion& m, std::size_t begin, std::size_t end,
                    std::chrono::microseconds period) {
  const auto start = std::chrono::steady_clock::now();
  for (std::size_t f = begin; f < end; ++f) {
    std::this_thread::sleep_until(start + period * static_cast<std::int64_t>(f - begin));
    ASSERT_TRUE(c.publish_frame(id, m.frame(f)).ok());
  }
}

// A test publisher's pace for `count` frames of `m`: fast, but never past
// what the server takes from a source at its declared rate (a token bucket
// holding a second of frames, at least 16: LiveSource), which drops the
// rest. The built-in walk (60 Hz, without ../shared/data) needs a slower
// pace than CMU's 120 Hz takes.
std::chrono::microseconds pace(const Motion& m, std::size_t count) {
  const double rate = m.frame_time > 0 ? 1.0 / m.frame_time : 120.0;
  const double burst = std::max(16.0, rate);
  const double slowest =
      count > burst ? 1.1 * (static_cast<double>(count) - burst) / (rate * static_cast<double>(count)) : 0.0;
  return std::max(std::chrono::microseconds(kSlowBuild ? 8000 : 2500),
                  std::chrono::microseconds(static_cast<std::int64_t>(slowest * 1e6)));
}

// A server with tokens, a publishing client and a subscribing ('control') one.
struct LiveRig {
  TestServer server{live_config()};
  std::unique_ptr<Client> pub = connect_as(server, kPublishToken);
  std::unique_ptr<Client> sub = connect_as(server, kControlToken);
};

client::PublishOptions live_options(const Motion& m, const std::string& name) {
  client::PublishOptions po;
  po.name = name;
  po.frame_time = m.frame_time;
  return po;
}

TEST(LivePublish, SubscribersOfEveryViewGetThePositionsOfThePublishedFrames) {
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  const std::size_t n = std::min<std::size_t>(source->frame_count, 150);
  const double tolerance = 1e-9 * skeleton_size(*source);
  const Skeleton& sk = source->skeleton;
  // A joint deep in the tree to re-root at, and another to see from.
  const std::string root = sk.joint(static_cast<int>(sk.size()) - 2).name;
  const std::string viewer = sk.joint(static_cast<int>(sk.size()) / 2).name;
  const Reference world = reference(*source, {}, n);
  const Reference rerooted = reference(*source, ViewSpec{.roots = {root}}, n);
  const Reference intrinsic = reference(*source, ViewSpec{.relative_to = viewer}, n);
  const Reference both = reference(*source, ViewSpec{.roots = {root}, .relative_to = viewer}, n);

  TestServer s(live_config());
  auto pub = connect_as(s, kPublishToken);
  auto sub1 = connect_as(s, kControlToken);
  auto sub2 = connect_as(s, kControlToken);
  ASSERT_TRUE(pub && sub1 && sub2);
  EXPECT_EQ(pub->hello().role, client::Role::kPublish);
  client::PublishOptions po;
  po.name = "studio/actor1";
  po.frame_time = source->frame_time;
  po.metres_per_unit = 0.01;
  const std::uint32_t id = pub->publish(source->skeleton, po).value().id;

  // Listed beside the library, live, with no frames yet.
  const auto motions = sub1->list_motions().value();
  const auto listed = std::find_if(motions.begin(), motions.end(), [](auto& m) { return m.name == "studio/actor1"; });
  ASSERT_NE(listed, motions.end());
  EXPECT_EQ(listed->source, "live");
  EXPECT_EQ(listed->frame_count, 0u);
  EXPECT_EQ(listed->joint_count, sk.size());
  EXPECT_DOUBLE_EQ(listed->metres_per_unit, 0.01);

  struct Case {
    std::string what;
    Client* client;
    const Reference* want;
    bool udp, shared, float64;
    std::string roots, relative_to;
  };
  const std::vector<Case> cases = {
      {"world, TCP", sub1.get(), &world, false, false, true, "", ""},
      {"re-rooted, TCP", sub1.get(), &rerooted, false, false, true, root, ""},
      {"intrinsic, UDP", sub1.get(), &intrinsic, true, false, true, "", viewer},
      {"re-rooted and intrinsic, TCP", sub2.get(), &both, false, false, true, root, viewer},
      {"world, shared, TCP (1)", sub2.get(), &world, false, true, true, "", ""},
      {"world, shared, TCP (2)", sub1.get(), &world, false, true, true, "", ""},
      {"world, float32", sub2.get(), &world, false, false, false, "", ""},
  };
  std::vector<std::unique_ptr<Watch>> watches;
  std::vector<client::SubscriptionInfo> subs;
  for (const auto& c : cases) {
    SCOPED_TRACE(c.what);
    auto v = c.client->create_view("studio/actor1");
    ASSERT_TRUE(v.ok()) << v.error().to_string();
    if (!c.roots.empty()) {
      v = c.client->set_roots(v->id, {c.roots});
      ASSERT_TRUE(v.ok());
    }
    if (!c.relative_to.empty()) {
      v = c.client->set_coordinates(v->id, c.relative_to);
      ASSERT_TRUE(v.ok());
    }
    watches.push_back(std::make_unique<Watch>());
    Watch& w = *watches.back();
    w.want = c.want;
    // float32 keeps about 7 digits of the skeleton's size.
    w.tolerance = c.float64 ? tolerance : 1e-6 * skeleton_size(*source);
    client::SubscribeOptions so;
    so.udp = c.udp;
    so.shared = c.shared;
    so.float64 = c.float64;
    subs.push_back(watch(*c.client, *v, so, w));
    EXPECT_NEAR(subs.back().rate_hz, 1.0 / source->frame_time, 1e-9);
  }
  EXPECT_EQ(subs[4].stream_id, subs[5].stream_id) << "the two shared subscriptions share one stream";
  EXPECT_TRUE(subs[5].joined_running);

  publish_frames(*pub, id, *source, 0, n, pace(*source, n));
  const Status unpublished = pub->unpublish(id);
  ASSERT_TRUE(unpublished.ok()) << unpublished.error().to_string();
  EXPECT_TRUE(pub->take_errors().empty());

  for (std::size_t i = 0; i < cases.size(); ++i) {
    SCOPED_TRACE(cases[i].what);
    Watch& w = *watches[i];
    const auto end = w.end.wait();
    ASSERT_TRUE(end.has_value()) << "no SubscriptionEnded";
    EXPECT_EQ(end->reason, "the live source ended");
    // Each frame was sent, or skipped by an edited view whose replays fell
    // behind (a sanitized build's replays are slow; the count says so).
    EXPECT_EQ(end->frames_sent + end->frames_skipped, n);
    std::lock_guard lock(w.mutex);
    EXPECT_EQ(w.bad, 0u) << w.first_problem;
    EXPECT_GT(w.compared, 0u);
    std::fprintf(stderr, "%s: %zu of %zu frames, %zu positions compared, worst %.3g\n", cases[i].what.c_str(),
                 w.indices.size(), n, w.compared, w.worst);
    if (cases[i].udp) {
      // Datagrams may be lost, the last one too: it may also arrive after
      // SubscriptionEnded (on TCP), when the client has let the subscription go.
      EXPECT_GE(w.indices.size(), n * 9 / 10);
    } else {
      // TCP: every frame arrives or is counted as dropped, in order.
      EXPECT_EQ(w.indices.size() + end->frames_dropped + end->frames_skipped, n);
      for (std::size_t k = 1; k < w.indices.size(); ++k) {
        EXPECT_LT(w.indices[k - 1], w.indices[k]);
        EXPECT_EQ(w.indices[k] - w.indices[k - 1], w.sequences[k] - w.sequences[k - 1]);
      }
      if (!w.indices.empty() && end->frames_skipped == 0) {
        EXPECT_EQ(w.indices.back(), n - 1);
      }
    }
  }
  // Gone from the list once ended.
  const auto after = sub1->list_motions().value();
  EXPECT_TRUE(std::none_of(after.begin(), after.end(), [](auto& m) { return m.name == "studio/actor1"; }));
  const auto stats = sub1->stats().value();
  EXPECT_EQ(stats.live_sources, 0u);
  EXPECT_EQ(stats.live_frames_received, n);
  EXPECT_EQ(stats.live_frames_refused, 0u);
}

TEST(LivePublish, AViewEditedMidStreamFollowsOnTheNextFrame) {
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  const std::size_t n = std::min<std::size_t>(source->frame_count, 60);
  const Reference world = reference(*source, {}, n);
  LiveRig rig;
  ASSERT_TRUE(rig.pub && rig.sub);
  auto& pub = rig.pub;
  auto& sub = rig.sub;
  const client::PublishOptions po = live_options(*source, "edited");
  const std::uint32_t id = pub->publish(source->skeleton, po).value().id;
  auto v = sub->create_view("edited").value();
  Watch w;
  w.want = &world;  // every root configuration keeps every joint's world position
  w.tolerance = 1e-9 * skeleton_size(*source);
  client::SubscribeOptions so;
  so.float64 = true;
  watch(*sub, v, so, w);
  publish_frames(*pub, id, *source, 0, n / 2, pace(*source, n));
  const std::string root = source->skeleton.joint(static_cast<int>(source->skeleton.size()) - 2).name;
  const auto edited = sub->set_roots(v.id, {root});
  ASSERT_TRUE(edited.ok()) << edited.error().to_string();
  EXPECT_EQ(edited->skeleton.roots().size(), 1u);
  EXPECT_EQ(edited->skeleton.joint(edited->skeleton.roots()[0]).name, root);
  publish_frames(*pub, id, *source, n / 2, n, pace(*source, n));
  ASSERT_TRUE(pub->unpublish(id).ok());
  const auto end = w.end.wait();
  ASSERT_TRUE(end.has_value());
  std::lock_guard lock(w.mutex);
  EXPECT_EQ(w.bad, 0u) << w.first_problem;
  // The frames after the edit came in the re-rooted skeleton.
  EXPECT_EQ(w.skeleton.joint(w.skeleton.roots()[0]).name, root);
  // Each frame arrived or was counted: dropped (TCP), or skipped while the
  // re-rooted view's replays were behind (a busy or sanitized build).
  EXPECT_EQ(w.indices.size() + end->frames_dropped + end->frames_skipped, n);
  EXPECT_GE(w.indices.size(), n / 2);
}

// A live source's views put on a rig (Retarget): each published frame is
// retargeted as it comes, and equals gmr::retarget of the whole take at that
// frame. Two views with the same rig share one replay per frame.
TEST(LivePublish, RetargetedViewsGetEachFrameOnTheRigFromOneReplay) {
  GMR_REQUIRE_DATA();
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  const std::size_t n = std::min<std::size_t>(source->frame_count, 60);
  auto rig = load_motion(data_file("bvh/mixamo/Beta_jump.bvh"));
  ASSERT_TRUE(rig.ok());
  auto on_rig = retarget(*source, *rig);
  ASSERT_TRUE(on_rig.ok()) << on_rig.error().to_string();
  auto expected = to_pre_rotation(*on_rig);
  ASSERT_TRUE(expected.ok());
  const Reference want = reference(*expected, {}, n);
  Watch watches[2];
  LiveRig live;
  ASSERT_TRUE(live.pub && live.sub);
  const std::uint32_t id = live.pub->publish(source->skeleton, live_options(*source, "lab")).value().id;
  for (Watch& w : watches) {
    auto v = live.sub->create_view("lab").value();
    auto retargeted = live.sub->retarget(v.id, rig->skeleton);
    ASSERT_TRUE(retargeted.ok()) << retargeted.error().to_string();
    w.want = &want;
    w.tolerance = 1e-9 * skeleton_size(*expected);
    client::SubscribeOptions so;
    so.float64 = true;
    watch(*live.sub, *retargeted, so, w);
  }
  publish_frames(*live.pub, id, *source, 0, n, pace(*source, n));
  ASSERT_TRUE(live.pub->unpublish(id).ok());
  std::vector<client::SubscriptionEnd> ends;
  for (Watch& w : watches) {
    const auto end = w.end.wait();
    ASSERT_TRUE(end.has_value());
    ends.push_back(*end);
  }
  const auto stats = live.sub->stats();
  ASSERT_TRUE(stats.ok()) << stats.error().to_string();
  for (std::size_t k = 0; k < 2; ++k) {
    Watch& w = watches[k];
    std::lock_guard lock(w.mutex);
    EXPECT_EQ(w.bad, 0u) << w.first_problem;
    EXPECT_EQ(w.skeleton.size(), rig->skeleton.size());
    EXPECT_EQ(w.indices.size() + ends[k].frames_dropped + ends[k].frames_skipped, n);
    // Every frame arrived or was counted; a sanitizer build retargets each
    // frame about ten times slower, and its replays skip more (ASan: 26 of 60
    // arrived once), so it is asked for fewer.
    const std::size_t least = kSlowBuild ? n / 6 : n / 2;
    EXPECT_GE(w.indices.size(), least);
    EXPECT_GE(w.compared, least * rig->skeleton.size());
    // A frame is skipped only when its replay never ran (the queue of
    // frames waiting was full); each replay served both views.
    EXPECT_EQ(stats->live_edit_replays, n - ends[k].frames_skipped);
  }
}

TEST(LivePublish, ALateSubscriberStartsAtTheNewestFrame) {
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  const Reference world = reference(*source, {}, 20);
  LiveRig rig;
  ASSERT_TRUE(rig.pub && rig.sub);
  auto& pub = rig.pub;
  auto& sub = rig.sub;
  const client::PublishOptions po = live_options(*source, "late");
  const std::uint32_t id = pub->publish(source->skeleton, po).value().id;
  publish_frames(*pub, id, *source, 0, 10, pace(*source, 12));
  // The server has all ten once it answers a request from the publisher
  // (requests on one connection are answered in order).
  ASSERT_TRUE(pub->list_motions().ok());
  auto v = sub->create_view("late").value();
  Watch w;
  w.want = &world;
  w.tolerance = 1e-9 * skeleton_size(*source);
  client::SubscribeOptions so;
  so.float64 = true;
  watch(*sub, v, so, w);
  // Its first frame is the newest, without waiting for the next.
  for (int i = 0; i < 200; ++i) {
    {
      std::lock_guard lock(w.mutex);
      if (!w.indices.empty()) break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  publish_frames(*pub, id, *source, 10, 12, pace(*source, 12));
  ASSERT_TRUE(pub->unpublish(id).ok());
  ASSERT_TRUE(w.end.wait().has_value());
  std::lock_guard lock(w.mutex);
  EXPECT_EQ(w.bad, 0u) << w.first_problem;
  ASSERT_EQ(w.indices.size(), 3u);
  EXPECT_EQ(w.indices[0], 9u);
  EXPECT_EQ(w.indices[1], 10u);
  EXPECT_EQ(w.indices[2], 11u);
}

TEST(LivePublish, ASourceThatDisconnectsEndsItsSubscribersCleanly) {
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  const Reference world = reference(*source, {}, 30);
  LiveRig rig;
  ASSERT_TRUE(rig.pub && rig.sub);
  auto& pub = rig.pub;
  auto& sub = rig.sub;
  const client::PublishOptions po = live_options(*source, "dropped");
  const std::uint32_t id = pub->publish(source->skeleton, po).value().id;
  auto v = sub->create_view("dropped").value();
  Watch tcp, udp;
  tcp.want = udp.want = &world;
  tcp.tolerance = udp.tolerance = 1e-9 * skeleton_size(*source);
  client::SubscribeOptions so;
  so.float64 = true;
  watch(*sub, v, so, tcp);
  so.udp = true;
  watch(*sub, v, so, udp);
  publish_frames(*pub, id, *source, 0, 30, pace(*source, 30));
  // A round trip: the server has taken all 30 (PublishFrame has no reply,
  // and close() drops what the client has not written yet).
  ASSERT_TRUE(pub->list_motions().ok());
  pub->close();  // mid-stream, without Unpublish
  for (Watch* w : {&tcp, &udp}) {
    const auto end = w->end.wait();
    ASSERT_TRUE(end.has_value());
    EXPECT_EQ(end->reason, "the live source disconnected");
    EXPECT_EQ(end->frames_sent, 30u);
    std::lock_guard lock(w->mutex);
    EXPECT_EQ(w->bad, 0u) << w->first_problem;
  }
  // The subscriber's connection goes on; the source is gone.
  const auto motions = sub->list_motions().value();
  EXPECT_TRUE(std::none_of(motions.begin(), motions.end(), [](auto& m) { return m.name == "dropped"; }));
  const auto again = sub->create_view("dropped");
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.error().message.find("NOT_FOUND"), std::string::npos);
  client::SubscribeOptions so2;
  const auto resub = sub->subscribe(v.id, so2, [](const ReceivedFrame&) {});
  ASSERT_FALSE(resub.ok());
  EXPECT_NE(resub.error().message.find("has ended"), std::string::npos) << resub.error().message;
  // The name is free for a new publication.
  auto pub2 = connect_as(rig.server, kPublishToken);
  ASSERT_TRUE(pub2);
  EXPECT_TRUE(pub2->publish(source->skeleton, po).ok());
}

TEST(LivePublish, TheServerRecordsASourceOnRequestAsAFileItsLibraryLoads) {
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  const std::size_t n = std::min<std::size_t>(source->frame_count, 80);
  TempDir dir;
  {
    // A server without --record-dir refuses to record.
    TestServer plain(live_config());
    auto pub = connect_as(plain, kPublishToken);
    ASSERT_TRUE(pub);
    client::PublishOptions po;
    po.name = "rec";
    po.record = true;
    const auto refused = pub->publish(source->skeleton, po);
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.error().message.find("FAILED_PRECONDITION: this server records no live sources"),
              std::string::npos)
        << refused.error().message;
  }
  server::ServerConfig cfg = live_config();
  cfg.record_dir = dir.path.string();
  TestServer s(cfg);
  auto pub = connect_as(s, kPublishToken);
  ASSERT_TRUE(pub);
  client::PublishOptions po;
  po.name = "stage/take 1";
  po.frame_time = source->frame_time;
  po.record = true;
  const auto publication = pub->publish(source->skeleton, po);
  ASSERT_TRUE(publication.ok()) << publication.error().to_string();
  const std::filesystem::path file = publication->recording;
  EXPECT_EQ(file.parent_path(), dir.path);
  EXPECT_EQ(file.extension(), ".gmrb");
  EXPECT_EQ(file.filename().string().rfind("stage_take_1-", 0), 0u) << file;
  publish_frames(*pub, publication->id, *source, 0, n, pace(*source, n));
  std::vector<double> nan(source->frame(0).begin(), source->frame(0).end());
  nan[0] = std::nan("");
  ASSERT_TRUE(pub->publish_frame(publication->id, nan).ok());  // refused: not recorded
  EXPECT_FALSE(std::filesystem::exists(file)) << "written before the source ended";
  ASSERT_TRUE(pub->unpublish(publication->id).ok());
  for (int i = 0; i < 1000 && !std::filesystem::exists(file); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(std::filesystem::exists(file));

  // Every frame as published: the same values, so the same positions.
  auto recorded = load_motion(file);
  ASSERT_TRUE(recorded.ok()) << recorded.error().to_string();
  ASSERT_EQ(recorded->frame_count, n);
  EXPECT_DOUBLE_EQ(recorded->frame_time, source->frame_time);
  const std::size_t joints = source->skeleton.size();
  std::vector<Eigen::Vector3d> rp(joints), sp(joints);
  std::vector<Eigen::Matrix3d> ro(joints), so(joints);
  double worst = 0;
  for (std::size_t f = 0; f < n; ++f) {
    compute_frame(*recorded, f, rp, ro);
    compute_frame(*source, f, sp, so);
    for (std::size_t j = 0; j < joints; ++j) worst = std::max(worst, (rp[j] - sp[j]).norm());
  }
  EXPECT_EQ(worst, 0.0);

  // Added to a library, it is a motion like the others.
  auto library = server::load_library(dir.path, 1);
  ASSERT_TRUE(library.ok());
  ASSERT_EQ(library->entries.size(), 1u);
  EXPECT_EQ(library->entries[0].motion->frame_count, n);
}

// A raw Publish request, for skeletons Client::publish would not build.
std::string publish_request(const std::string& name, const pb::Skeleton& skeleton, double frame_time) {
  pb::ClientMessage m;
  m.mutable_publish()->set_name(name);
  *m.mutable_publish()->mutable_skeleton() = skeleton;
  m.mutable_publish()->set_frame_time(frame_time);
  return m.SerializeAsString();
}

pb::ServerMessage parse(const Result<std::string>& bytes) {
  pb::ServerMessage m;
  EXPECT_TRUE(bytes.ok());
  if (bytes.ok()) {
    EXPECT_TRUE(m.ParseFromString(*bytes));
  }
  return m;
}

TEST(LivePublish, BadSkeletonsAndFramesGetErrorsAndNeverReachSubscribers) {
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  const Reference world = reference(*source, {}, 10);
  TestServer s(live_config());
  auto pub = connect_as(s, kPublishToken);
  auto control = connect_as(s, kControlToken);
  ASSERT_TRUE(pub && control);
  client::PublishOptions po;
  po.name = "checked";
  po.frame_time = source->frame_time;

  // Only a 'publish' role may publish.
  const auto denied = control->publish(source->skeleton, po);
  ASSERT_FALSE(denied.ok());
  EXPECT_NE(denied.error().message.find("PERMISSION_DENIED"), std::string::npos) << denied.error().message;

  pb::Skeleton good;
  wire::to_proto(source->skeleton, good);
  struct Bad {
    std::string what;
    std::string name;
    pb::Skeleton skeleton;
    double frame_time;
    pb::ErrorCode code;
    std::string says;
  };
  std::vector<Bad> bad;
  {
    pb::Skeleton s2 = good;
    s2.mutable_joints(2)->set_parent(5);  // a parent after its child
    bad.push_back({"parent after child", "x", s2, 0.01, pb::ERROR_CODE_BAD_REQUEST, "parent"});
  }
  {
    pb::Skeleton s2 = good;
    s2.mutable_joints(3)->set_name(s2.joints(1).name());
    bad.push_back({"duplicate name", "x", s2, 0.01, pb::ERROR_CODE_BAD_REQUEST, s2.joints(1).name()});
  }
  {
    pb::Skeleton s2 = good;
    s2.mutable_joints(1)->set_parent(1000);
    bad.push_back({"parent out of range", "x", s2, 0.01, pb::ERROR_CODE_BAD_REQUEST, "parent"});
  }
  {
    // Joint names reach every subscriber's terminal: the source names' rule.
    pb::Skeleton s2 = good;
    s2.mutable_joints(2)->set_name("Spine\x1b[2J\x07");
    bad.push_back({"a joint name with ESC", "x", s2, 0.01, pb::ERROR_CODE_BAD_REQUEST,
                   "joint 2 name \"Spine\\x1b[2J\\x07\": the name has a control character (U+001B"});
    s2.mutable_joints(2)->set_name("Spine\nframe,Head,0,0,0");
    bad.push_back({"a joint name with a line break", "x", s2, 0.01, pb::ERROR_CODE_BAD_REQUEST, "(U+000A"});
  }
  bad.push_back({"a zero-width space in the source name", "walk\xE2\x80\x8B", good, 0.01, pb::ERROR_CODE_BAD_REQUEST,
                 "invisible or look-alike character (U+200B"});
  bad.push_back({"a right-to-left override in the source name", "\xE2\x80\xAEklaw", good, 0.01,
                 pb::ERROR_CODE_BAD_REQUEST, "(U+202E"});
  bad.push_back({"no joints", "x", pb::Skeleton{}, 0.01, pb::ERROR_CODE_BAD_REQUEST, "no joints"});
  bad.push_back({"no name", "", good, 0.01, pb::ERROR_CODE_BAD_REQUEST, "name"});
  bad.push_back({"a library motion's name", "walk", good, 0.01, pb::ERROR_CODE_FAILED_PRECONDITION, "already served"});
  bad.push_back({"frame time 0", "x", good, 0.0, pb::ERROR_CODE_BAD_REQUEST, "frame time"});
  bad.push_back({"frame time NaN", "x", good, std::nan(""), pb::ERROR_CODE_BAD_REQUEST, "frame time"});
  for (const auto& b : bad) {
    SCOPED_TRACE(b.what);
    const pb::ServerMessage r = parse(pub->request_raw(publish_request(b.name, b.skeleton, b.frame_time)));
    ASSERT_TRUE(r.has_error()) << r.DebugString();
    EXPECT_EQ(r.error().code(), b.code);
    EXPECT_NE(r.error().message().find(b.says), std::string::npos) << r.error().message();
  }

  const std::uint32_t id = pub->publish(source->skeleton, po).value().id;
  const auto twice = pub->publish(source->skeleton, po);
  ASSERT_FALSE(twice.ok());
  EXPECT_NE(twice.error().message.find("already served"), std::string::npos);
  auto v = control->create_view("checked").value();
  Watch w;
  w.want = &world;
  w.tolerance = 1e-9 * skeleton_size(*source);
  client::SubscribeOptions so;
  so.float64 = true;
  watch(*control, v, so, w);

  const std::size_t stride = source->stride();
  std::vector<double> short_frame(source->frame(0).begin(), source->frame(0).end() - 1);
  std::vector<double> nan_frame(source->frame(0).begin(), source->frame(0).end());
  nan_frame[stride - 1] = std::nan("");
  ASSERT_TRUE(pub->publish_frame(id, source->frame(0)).ok());
  ASSERT_TRUE(pub->publish_frame(id, short_frame).ok());  // queued: the server refuses it
  ASSERT_TRUE(pub->publish_frame(id, nan_frame).ok());
  ASSERT_TRUE(pub->publish_frame(id + 7, source->frame(1)).ok());
  ASSERT_TRUE(pub->publish_frame(id, source->frame(1)).ok());
  ASSERT_TRUE(pub->list_motions().ok());  // answered after every frame before it
  const auto errors = pub->take_errors();
  ASSERT_EQ(errors.size(), 3u);
  EXPECT_NE(errors[0].find("BAD_REQUEST: live 'checked': frame 1 has " + std::to_string(stride - 1) + " values"),
            std::string::npos)
      << errors[0];
  EXPECT_NE(errors[1].find("is not finite"), std::string::npos) << errors[1];
  EXPECT_NE(errors[1].find(source->skeleton.joint(static_cast<int>(source->skeleton.size()) - 1).name),
            std::string::npos)
      << errors[1];
  EXPECT_NE(errors[2].find("NOT_FOUND: unknown publication"), std::string::npos) << errors[2];
  ASSERT_TRUE(pub->unpublish(id).ok());
  ASSERT_TRUE(w.end.wait().has_value());
  {
    std::lock_guard lock(w.mutex);
    EXPECT_EQ(w.bad, 0u) << w.first_problem;
    // Only the two good frames, as frames 0 and 1 with their own positions.
    ASSERT_EQ(w.indices.size(), 2u);
    EXPECT_EQ(w.indices[0], 0u);
    EXPECT_EQ(w.indices[1], 1u);
    EXPECT_EQ(w.sequences[1], w.sequences[0] + 1);
  }
  const auto stats = control->stats().value();
  EXPECT_EQ(stats.live_frames_received, 2u);
  EXPECT_EQ(stats.live_frames_refused, 3u);
  // A live subscription cannot seek, and the source's name is free again.
  EXPECT_FALSE(control->create_view("checked").ok());
}

// ---- Replicas sharing live sources through NATS

#ifdef GMR_SERVER_PATH

// A child process (nats-server, a gmr-server replica) with its output in a
// log file; killed (SIGKILL) and reaped when it goes.
struct Child {
  pid_t pid = -1;
  std::filesystem::path log;
  Child(const std::vector<std::string>& argv, std::filesystem::path log_file) : log(std::move(log_file)) {
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    pid = ::fork();
    if (pid == 0) {
      const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
      if (fd >= 0) {
        ::dup2(fd, 1);
        ::dup2(fd, 2);
      }
      ::execv(args[0], args.data());
      std::_Exit(127);
    }
  }
  void kill() {
    if (pid <= 0) return;
    ::kill(pid, SIGKILL);
    ::waitpid(pid, nullptr, 0);
    pid = -1;
  }
  ~Child() { kill(); }
  std::string output() const {
    std::ifstream in(log);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
};

std::uint16_t free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t n = sizeof a;
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

bool accepts(std::uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(port);
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  ::close(fd);
  return ok;
}

// nats-server on a free loopback port, or why not.
std::string nats_server_binary() {
  for (const char* p : {"/usr/sbin/nats-server", "/usr/bin/nats-server"}) {
    if (::access(p, X_OK) == 0) return p;
  }
  return {};
}

#define GMR_REQUIRE_NATS(binary)                                                                                \
  const std::string binary = nats_server_binary();                                                              \
  if (binary.empty()) {                                                                                         \
    const char* ci = std::getenv("CI");                                                                         \
    if (ci != nullptr && std::string(ci) == "true") FAIL() << "nats-server is not installed (install-deps.sh)"; \
    GTEST_SKIP() << "nats-server is not installed: scripts/install-deps.sh installs it";                        \
  }

std::unique_ptr<Child> start_nats(const std::string& binary, std::uint16_t port, const TempDir& dir) {
  auto nats = std::make_unique<Child>(std::vector<std::string>{binary, "-a", "127.0.0.1", "-p", std::to_string(port)},
                                      dir.path / ("nats-" + std::to_string(port) + ".log"));
  for (int i = 0; i < 500 && !accepts(port); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_TRUE(accepts(port)) << nats->output();
  return nats;
}

// Waits until `c`'s server lists `motion` (or no longer does, with `listed` false).
bool wait_listed(Client& c, const std::string& motion, bool listed = true) {
  for (int i = 0; i < 1000; ++i) {
    const auto motions = c.list_motions();
    if (motions.ok() &&
        std::any_of(motions->begin(), motions->end(), [&](auto& m) { return m.name == motion; }) == listed) {
      return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

TEST(LiveReplicas, ASourcePublishedOnOneReplicaStreamsFromAnotherAndEndsWhenItsReplicaIsKilled) {
  GMR_REQUIRE_NATS(nats_binary);
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  const std::size_t n = std::min<std::size_t>(source->frame_count, 120);
  const Skeleton& sk = source->skeleton;
  const std::string root = sk.joint(static_cast<int>(sk.size()) - 2).name;
  const std::string viewer = sk.joint(static_cast<int>(sk.size()) / 2).name;
  const Reference world = reference(*source, {}, n);
  const Reference both = reference(*source, ViewSpec{.roots = {root}, .relative_to = viewer}, n);
  TempDir dir;
  const std::uint16_t nats_port = free_port();
  auto nats = start_nats(nats_binary, nats_port, dir);
  const std::string url = "nats://127.0.0.1:" + std::to_string(nats_port);

  // Replica A: a process of its own (it is killed below), B: in this process.
  {
    std::ofstream auth(dir.path / "auth.txt");
    auth << "publish " << kPublishToken << "\ncontrol " << kControlToken << "\n";
  }
  std::filesystem::permissions(dir.path / "auth.txt",
                               std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
  Child a({GMR_SERVER_PATH, "--port", "0", "--port-file", (dir.path / "port_a").string(), "--http-port", "-1",
           "--auth-file", (dir.path / "auth.txt").string(), "--nats", url, "--log-level", "info"},
          dir.path / "replica_a.log");
  std::uint16_t port_a = 0;
  for (int i = 0; i < 1000 && port_a == 0; ++i) {
    std::ifstream in(dir.path / "port_a");
    if (!(in >> port_a)) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_NE(port_a, 0) << a.output();
  server::ServerConfig cfg = live_config();
  cfg.nats_url = url;
  cfg.relay_timeout = std::chrono::milliseconds(1500);
  TestServer b(cfg);

  client::ClientOptions to_a;
  to_a.host = "127.0.0.1";
  to_a.port = port_a;
  to_a.auth_token = kPublishToken;
  auto pub = Client::connect(to_a);
  ASSERT_TRUE(pub.ok()) << pub.error().to_string();
  auto sub = connect_as(b, kControlToken);
  ASSERT_TRUE(sub);
  client::PublishOptions po;
  po.name = "replicated";
  po.frame_time = source->frame_time;
  const std::uint32_t id = (*pub)->publish(source->skeleton, po).value().id;
  ASSERT_TRUE(wait_listed(*sub, "replicated")) << "replica B never heard of the source";

  // Two views on B: the world, and re-rooted seen from a joint.
  Watch w1, w2;
  w1.want = &world;
  w2.want = &both;
  w1.tolerance = w2.tolerance = 1e-9 * skeleton_size(*source);
  client::SubscribeOptions so;
  so.float64 = true;
  watch(*sub, sub->create_view("replicated").value(), so, w1);
  auto v2 = sub->create_view("replicated").value();
  v2 = sub->set_roots(v2.id, {root}).value();
  v2 = sub->set_coordinates(v2.id, viewer).value();
  watch(*sub, v2, so, w2);
  publish_frames(**pub, id, *source, 0, n, pace(*source, n));
  for (Watch* w : {&w1, &w2}) {
    // Until the last frame arrived, or none arrived for 3 s: the frames come
    // through NATS and replica B's fan-out, which on a busy machine (a
    // sanitizer build beside another test) took over 5 s.
    std::size_t seen = 0;
    auto quiet_since = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - quiet_since < std::chrono::seconds(3)) {
      {
        std::lock_guard lock(w->mutex);
        if (!w->indices.empty() && w->indices.back() == n - 1) break;
        if (w->indices.size() != seen) {
          seen = w->indices.size();
          quiet_since = std::chrono::steady_clock::now();
        }
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::lock_guard lock(w->mutex);
    EXPECT_EQ(w->bad, 0u) << w->first_problem;
    ASSERT_FALSE(w->indices.empty());
    // A slow (sanitizer) build may skip frames for a subscriber it cannot
    // keep up with, the last one too (a live source has no later frame to
    // replace it); those are counted below, at the end.
    if (!kSlowBuild) {
      EXPECT_GE(w->indices.size(), n * 9 / 10);
      EXPECT_EQ(w->indices.back(), n - 1);
    }
    std::fprintf(stderr, "replica B: %zu of %zu frames, %zu positions compared, worst %.3g\n", w->indices.size(), n,
                 w->compared, w->worst);
  }

  // Replica A dies without a word: B ends its subscribers, and goes on.
  a.kill();
  for (Watch* w : {&w1, &w2}) {
    const auto end = w->end.wait(std::chrono::seconds(10));
    ASSERT_TRUE(end.has_value()) << "B's subscriber was not ended";
    EXPECT_EQ(end->reason, "the replica publishing the live source went away");
    // Every relayed frame was delivered, or counted: dropped (TCP, in
    // order), or skipped by an edited view whose replays fell behind a
    // burst (a busy machine).
    EXPECT_EQ(end->frames_sent + end->frames_skipped, n);
    std::lock_guard lock(w->mutex);
    EXPECT_EQ(w->indices.size() + end->frames_dropped + end->frames_skipped, n);
  }
  EXPECT_TRUE(wait_listed(*sub, "replicated", false));
  EXPECT_TRUE(sub->list_motions().ok());
}

TEST(LiveReplicas, NatsGoingAwayIsLoggedRetriedAndSurvived) {
  GMR_REQUIRE_NATS(nats_binary);
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  TempDir dir;
  const std::uint16_t nats_port = free_port();
  auto nats = start_nats(nats_binary, nats_port, dir);
  server::ServerConfig cfg = live_config();
  cfg.nats_url = "nats://127.0.0.1:" + std::to_string(nats_port);
  TestServer a(cfg), b(cfg);
  auto pub = connect_as(a, kPublishToken);
  auto sub = connect_as(b, kControlToken);
  ASSERT_TRUE(pub && sub);
  client::PublishOptions po;
  po.name = "first";
  po.frame_time = source->frame_time;
  const std::uint32_t first = pub->publish(source->skeleton, po).value().id;
  ASSERT_TRUE(wait_listed(*sub, "first"));

  nats->kill();
  // Both replicas go on: frames are accepted on A (not relayed), B streams its library.
  for (std::size_t f = 0; f < 10; ++f) ASSERT_TRUE(pub->publish_frame(first, source->frame(f)).ok());
  ASSERT_TRUE(pub->list_motions().ok());
  EXPECT_TRUE(pub->take_errors().empty());
  auto walk = sub->create_view("walk");
  ASSERT_TRUE(walk.ok());
  Latch<std::uint64_t> got;
  client::SubscribeOptions so;
  so.max_frames = 5;
  ASSERT_TRUE(sub->subscribe(walk->id, so, [&](const ReceivedFrame& f) { got.set(f.frame_index); }).ok());
  EXPECT_TRUE(got.wait(std::chrono::seconds(5)).has_value());

  // NATS back on the same port: both reconnect, and a new source reaches B.
  nats = start_nats(nats_binary, nats_port, dir);
  po.name = "second";
  ASSERT_TRUE(pub->publish(source->skeleton, po).ok());
  EXPECT_TRUE(wait_listed(*sub, "second")) << "B did not hear of a source published after NATS came back";
}

// The relay with NATS credentials and a shared secret (docs/deployment.md):
// two replicas that hold both share a source; a publisher on the subject
// that has the NATS credentials but not the secret is refused and counted,
// whatever it sends (an old-style message, a forged MAC, a real message
// replayed); a replica without the credentials is kept out by NATS itself.
TEST(LiveReplicas, RelayMessagesNeedTheSharedSecretAndNatsTheCredentials) {
  GMR_REQUIRE_NATS(nats_binary);
  const auto source = source_motion();
  ASSERT_NE(source, nullptr);
  TempDir dir;
  const std::uint16_t nats_port = free_port();
  const std::string password = "nats-pw-6f1e0c9a83b24d57a1e8c3f0";
  {
    std::ofstream conf(dir.path / "nats.conf");
    conf << "listen: 127.0.0.1:" << nats_port << "\nauthorization {\n  users = [ {user: gmr, password: \"" << password
         << "\"} ]\n}\n";
    std::ofstream creds(dir.path / "nats.creds");
    creds << "# gmr's NATS user\nuser gmr\npassword " << password << "\n";
  }
  Child nats({nats_binary, "-c", (dir.path / "nats.conf").string()}, dir.path / "nats.log");
  for (int i = 0; i < 500 && !accepts(nats_port); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_TRUE(accepts(nats_port)) << nats.output();
  const std::string url = "nats://127.0.0.1:" + std::to_string(nats_port);

  server::ServerConfig cfg = live_config();
  cfg.nats_url = url;
  cfg.nats_credentials_file = (dir.path / "nats.creds").string();
  cfg.relay_secret = "relay-secret-3c9d1f7a0b6e4852c1d9a7f3e5b08264";
  TestServer a(cfg), b(cfg);
  // A replica without the NATS credentials is refused by NATS: at start
  // (it does not start, saying why) or, when the refusal comes after it
  // started (a slow machine), it is never connected and logs why.
  server::ServerConfig outsider = cfg;
  outsider.nats_credentials_file.clear();
  try {
    TestServer refused(outsider);
    for (int i = 0; i < 100; ++i) {
      EXPECT_FALSE(refused.server.stats().relay_connected);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("--nats-creds"), std::string::npos) << e.what();
  }
  for (int i = 0; i < 500 && !a.server.stats().relay_connected; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(a.server.stats().relay_connected);

  auto pub = connect_as(a, kPublishToken);
  auto sub = connect_as(b, kControlToken);
  ASSERT_TRUE(pub && sub);

  // A rogue on the subject: it has the NATS credentials, not the secret.
  natsConnection* rogue = nullptr;
  natsOptions* opts = nullptr;
  ASSERT_EQ(natsOptions_Create(&opts), NATS_OK);
  natsOptions_SetURL(opts, url.c_str());
  natsOptions_SetUserInfo(opts, "gmr", password.c_str());
  ASSERT_EQ(natsConnection_Connect(&rogue, opts), NATS_OK);
  natsOptions_Destroy(opts);
  natsSubscription* tap = nullptr;
  ASSERT_EQ(natsConnection_SubscribeSync(&tap, rogue, cfg.nats_subject.c_str()), NATS_OK);

  client::PublishOptions po;
  po.name = "replicated";
  po.frame_time = source->frame_time;
  const std::uint32_t id = pub->publish(source->skeleton, po).value().id;
  ASSERT_TRUE(wait_listed(*sub, "replicated")) << "replica B never heard of the source";
  // A real message of replica A, as the rogue saw it go by.
  natsMsg* captured = nullptr;
  ASSERT_EQ(natsSubscription_NextMsg(&captured, tap, 5000), NATS_OK);
  const std::string real(natsMsg_GetData(captured), static_cast<std::size_t>(natsMsg_GetDataLength(captured)));
  natsMsg_Destroy(captured);

  const auto publish = [&](const std::string& bytes) {
    ASSERT_EQ(natsConnection_Publish(rogue, cfg.nats_subject.c_str(), bytes.data(), static_cast<int>(bytes.size())),
              NATS_OK);
  };
  relay::v1::LiveRelay forged;
  forged.set_origin("0123456789abcdef");
  forged.set_serial(1);
  forged.set_sequence(1);
  forged.mutable_announce()->set_name("rogue/forged");
  wire::to_proto(source->skeleton, *forged.mutable_announce()->mutable_skeleton());
  forged.mutable_announce()->set_frame_time(source->frame_time);
  publish(forged.SerializeAsString());  // the format before signing
  relay::v1::SignedRelay wrong_mac;
  wrong_mac.set_relay(forged.SerializeAsString());
  wrong_mac.set_mac(std::string(32, 'x'));
  publish(wrong_mac.SerializeAsString());
  relay::v1::SignedRelay no_mac;
  no_mac.set_relay(forged.SerializeAsString());
  publish(no_mac.SerializeAsString());
  // A real message replayed once A has moved on (it re-announces every second).
  std::this_thread::sleep_for(std::chrono::milliseconds(1200));
  publish(real);
  natsConnection_Flush(rogue);

  // B refused all four; A the three forged ones (the replayed message is
  // its own, which it ignores). Nothing of the rogue's is listed.
  for (auto [r, want] : {std::pair{&a, 3u}, std::pair{&b, 4u}}) {
    std::uint64_t refused = 0;
    for (int i = 0; i < 500 && refused < want; ++i) {
      refused = r->server.stats().relay_messages_refused;
      if (refused < want) std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    EXPECT_EQ(r->server.stats().relay_messages_refused, want);
  }
  EXPECT_TRUE(wait_listed(*sub, "rogue/forged", false));
  const auto listed = sub->list_motions().value();
  EXPECT_TRUE(std::none_of(listed.begin(), listed.end(), [](auto& m) { return m.name == "rogue/forged"; }));
  // Replica B still streams A's source.
  auto view = sub->create_view("replicated");
  ASSERT_TRUE(view.ok());
  Latch<std::uint64_t> got;
  client::SubscribeOptions so;
  ASSERT_TRUE(sub->subscribe(view->id, so, [&](const ReceivedFrame& f) { got.set(f.frame_index); }).ok());
  for (std::size_t f = 0; f < 40 && !got.wait(std::chrono::milliseconds(0)); ++f) {
    ASSERT_TRUE(pub->publish_frame(id, source->frame(f % source->frame_count)).ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(got.wait(std::chrono::seconds(5)).has_value()) << "no frame of A's source reached B";

  natsSubscription_Destroy(tap);
  natsConnection_Destroy(rogue);
}

#endif  // GMR_SERVER_PATH

}  // namespace
}  // namespace gmr::test
