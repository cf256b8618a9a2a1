// Structural view edits of long motions are computed on the server's edit
// thread: while one runs, other clients' requests are answered and their
// frames go on, and the editing connection's next requests wait and are
// answered in order after it.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <functional>
#include <thread>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/server/library.h"
#include "gmr/server/view.h"
#include "gmr/skeleton/skeleton.h"
#include "net_test_util.h"

namespace gmr::test {
namespace {

// The built-in walk repeated to `frames` frames: long enough that an edit of
// it takes a good part of a second.
std::shared_ptr<const Motion> long_walk(std::size_t frames) {
  for (const auto& e : server::builtin_library()) {
    if (e.name != "walk") continue;
    Motion m = *e.motion;
    const Motion& w = *e.motion;
    m.frame_count = frames;
    m.values.resize(frames * m.stride());
    for (std::size_t f = 0; f < frames; ++f) {
      const auto src = w.frame(f % w.frame_count);
      std::copy(src.begin(), src.end(), m.frame(f).begin());
    }
    return std::make_shared<const Motion>(std::move(m));
  }
  ADD_FAILURE() << "no built-in walk";
  return nullptr;
}

// Frames of the walk whose edit takes about half a second in this build,
// at most 40,000 (0.2-0.4 s in Release): sanitizer builds edit 3 to 75
// times slower, and the test needs an edit long enough for other clients to
// be answered meanwhile, yet short enough for the client's 5 s timeout.
std::size_t long_frames() {
  static const std::size_t frames = [] {
    constexpr std::size_t kProbe = 500;
    const auto m = long_walk(kProbe);
    server::View v(1, "probe", m);
    const auto start = std::chrono::steady_clock::now();
    auto edit = v.edit_shift_root(m->skeleton.joint(static_cast<int>(m->skeleton.size()) - 1).name);
    EXPECT_TRUE(edit.ok() && edit->run().ok());
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double wanted = 0.5 / std::max(seconds, 1e-6) * kProbe;
    return static_cast<std::size_t>(std::clamp(wanted, 500.0, 40'000.0));
  }();
  return frames;
}

struct EditServer {
  EditServer() : s(config(), library()) {}
  static server::ServerConfig config() {
    server::ServerConfig cfg;
    cfg.max_view_bytes_per_connection = std::size_t{1} << 30;
    return cfg;
  }
  std::vector<server::LibraryEntry> library() {
    auto lib = test_library();
    motion = long_walk(long_frames());
    server::LibraryEntry& e = lib.emplace_back();
    e.name = "long";
    e.source = "builtin";
    e.motion = motion;
    e.metres_per_unit = 0.01;
    return lib;
  }
  std::shared_ptr<const Motion> motion;
  TestServer s;
};

// The positions of every joint of `frame` in the reply `r` to a QueryFrames
// that listed `names`, against the library motion's.
double worst_position_error(const pb::ServerMessage& r, const Motion& m, std::size_t frame) {
  std::vector<Eigen::Vector3d> p(m.skeleton.size());
  compute_frame(m, frame, p);
  double worst = 0;
  EXPECT_EQ(r.frames().positions_size(), static_cast<int>(3 * p.size()));
  if (r.frames().positions_size() != static_cast<int>(3 * p.size())) return 1e9;
  for (std::size_t j = 0; j < p.size(); ++j) {
    for (int k = 0; k < 3; ++k) {
      worst = std::max(worst, std::abs(r.frames().positions(static_cast<int>(3 * j) + k) - p[j][k]));
    }
  }
  return worst;
}

pb::ClientMessage query(std::uint64_t id, std::uint32_t view, std::size_t frame, const Motion& m) {
  pb::ClientMessage q = request(id);
  q.mutable_query_frames()->set_view_id(view);
  q.mutable_query_frames()->set_begin(static_cast<std::uint32_t>(frame));
  for (const auto& j : m.skeleton.joints()) q.mutable_query_frames()->add_joints(j.name);
  return q;
}

TEST(ViewEdits, ALongEditRunsOffTheIoThreadAndTheConnectionsNextRequestsWaitInOrder) {
  EditServer es;
  const Motion& m = *es.motion;
  ASSERT_GT(m.values.size(), server::ServerConfig{}.edit_inline_values);

  // Another client streams the walk at 120 Hz and counts its frames (the
  // count outlives the client, whose thread may deliver one more).
  std::atomic<std::uint64_t> frames{0};
  auto other = es.s.connect();
  auto walk = other->create_view("walk");
  ASSERT_TRUE(walk.ok()) << walk.error().to_string();
  auto sub = other->subscribe(walk->id, {.loop = true}, [&](const client::ReceivedFrame&) { ++frames; });
  ASSERT_TRUE(sub.ok()) << sub.error().to_string();

  RawConnection editor(es.s.port());
  editor.handshake();
  auto view = editor.create_view(2, "long");
  ASSERT_TRUE(view.has_value());
  const std::string leaf = m.skeleton.joint(static_cast<int>(m.skeleton.size()) - 1).name;
  const std::string first_root = m.skeleton.joint(0).name;

  // One write: the edit, then a query that must see the edited view.
  pb::ClientMessage roots = request(10);
  roots.mutable_set_roots()->set_view_id(*view);
  roots.mutable_set_roots()->add_roots(leaf);
  roots.mutable_set_roots()->add_roots(first_root);
  const std::size_t some_frame = 777 % m.frame_count;
  std::string bytes = wire::frame_message(roots).value() + wire::frame_message(query(11, *view, some_frame, m)).value();
  // And an edit the library refuses (a root listed twice), computed off the
  // thread too, then a query of the view as the first edit left it.
  pb::ClientMessage twice = request(12);
  twice.mutable_set_roots()->set_view_id(*view);
  twice.mutable_set_roots()->add_roots(leaf);
  twice.mutable_set_roots()->add_roots(leaf);
  bytes += wire::frame_message(twice).value() + wire::frame_message(query(13, *view, m.frame_count - 1, m)).value();
  const std::uint64_t frames_before = frames.load();
  const auto sent = std::chrono::steady_clock::now();
  editor.send_bytes(bytes);

  // While the edit runs, the other client is answered and gets frames.
  std::size_t answered_during_edit = 0;
  while (!editor.readable(std::chrono::milliseconds(1)) &&
         std::chrono::steady_clock::now() - sent < std::chrono::seconds(60)) {
    auto motions = other->list_motions();
    ASSERT_TRUE(motions.ok()) << motions.error().to_string();
    ++answered_during_edit;
  }
  const std::uint64_t frames_during_edit = frames.load() - frames_before;
  const std::optional<pb::ServerMessage> first = editor.reply(std::chrono::seconds(60));
  ASSERT_TRUE(first.has_value()) << "no answer to the edit";
  std::printf(
      "the edit of %zu values took %.0f ms; meanwhile the other client had %zu requests answered and %llu "
      "frames\n",
      m.values.size(), std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - sent).count(),
      answered_during_edit, static_cast<unsigned long long>(frames_during_edit));
  // Computed on the I/O thread, the edit lets through at most the one request
  // that came before it (measured: 1); off it, hundreds (measured: 310).
  EXPECT_GE(answered_during_edit, 10u) << "the edit held the I/O thread";

  // The editor's answers, in the order asked.
  ASSERT_EQ(first->request_id(), 10u) << first->DebugString();
  ASSERT_TRUE(first->has_view()) << first->DebugString();
  EXPECT_EQ(first->view().skeleton_version(), 2u);
  int roots_seen = 0;
  for (const auto& j : first->view().skeleton().joints()) roots_seen += j.parent() < 0 ? 1 : 0;
  EXPECT_EQ(roots_seen, 2);
  auto second = editor.reply(std::chrono::seconds(60));
  ASSERT_TRUE(second.has_value() && second->has_frames()) << (second ? second->DebugString() : "no reply");
  EXPECT_EQ(second->request_id(), 11u);
  EXPECT_LE(worst_position_error(*second, m, some_frame), 1e-9 * skeleton_size(m));
  auto third = editor.reply(std::chrono::seconds(60));
  ASSERT_TRUE(third.has_value() && third->has_error()) << (third ? third->DebugString() : "no reply");
  EXPECT_EQ(third->request_id(), 12u);
  EXPECT_EQ(third->error().code(), pb::ERROR_CODE_FAILED_PRECONDITION);
  EXPECT_NE(third->error().message().find("set roots"), std::string::npos) << third->error().message();
  auto fourth = editor.reply(std::chrono::seconds(60));
  ASSERT_TRUE(fourth.has_value() && fourth->has_frames()) << (fourth ? fourth->DebugString() : "no reply");
  EXPECT_EQ(fourth->request_id(), 13u);
  EXPECT_LE(worst_position_error(*fourth, m, m.frame_count - 1), 1e-9 * skeleton_size(m));
}

// A client that goes away while its edit runs: the edit finishes unseen, the
// server stays up, and the edit thread serves the next one.
TEST(ViewEdits, AClientThatLeavesMidEditLeavesNothingBehind) {
  EditServer es;
  const Motion& m = *es.motion;
  {
    RawConnection editor(es.s.port());
    editor.handshake();
    auto view = editor.create_view(2, "long");
    ASSERT_TRUE(view.has_value());
    pb::ClientMessage shift = request(3);
    shift.mutable_shift_root()->set_view_id(*view);
    shift.mutable_shift_root()->set_joint(m.skeleton.joint(static_cast<int>(m.skeleton.size()) - 1).name);
    editor.send(shift);
  }  // closed at once
  auto c = es.s.connect();
  auto v = c->create_view("long");
  ASSERT_TRUE(v.ok()) << v.error().to_string();
  auto s = c->strip_dummies(v->id);
  ASSERT_TRUE(s.ok()) << s.error().to_string();
  const std::string leaf = m.skeleton.joint(static_cast<int>(m.skeleton.size()) - 1).name;
  auto shifted = c->shift_root(v->id, leaf);
  ASSERT_TRUE(shifted.ok()) << shifted.error().to_string();
  EXPECT_TRUE(shifted->skeleton.is_root(shifted->skeleton.find(leaf)));
}

// An edit of a view that float32 streams played compiles the new float form
// with the edit (on the edit thread), not at the streams' next frame on the
// I/O thread; a view nobody played in float32 leaves it for later.
// Live views whose edits are the same spell the same key (the source then
// replays them once a frame for all: LivePublish.RetargetedViewsGetEach...);
// any difference in an edit, its joint, its rig or their order, another key.
TEST(ViewEdits, LiveViewsWithTheSameEditsShareAKeyAndOthersDoNot) {
  const auto walk = long_walk(1);
  ASSERT_NE(walk, nullptr);
  auto bigger = std::make_shared<Motion>(*walk);  // the walk's rig, one bone longer
  {
    auto joints = bigger->skeleton.joints();
    joints[static_cast<std::size_t>(bigger->skeleton.find("r_knee"))].offset *= 1.25;
    bigger->skeleton = Skeleton::create(std::move(joints)).value();
  }
  using Edit = std::function<Result<server::ViewEdit>(const server::View&)>;
  // The key of a fresh live view of the walk after `edits`.
  auto key = [&](const std::vector<Edit>& edits) -> std::string {
    server::View v(1, "live", walk, std::weak_ptr<server::LiveSource>());
    for (const auto& e : edits) {
      auto edit = e(v);
      EXPECT_TRUE(edit.ok()) << edit.error().to_string();
      if (!edit.ok()) return {};
      auto next = edit->run();
      EXPECT_TRUE(next.ok()) << next.error().to_string();
      if (!next.ok()) return {};
      EXPECT_TRUE(v.commit(*edit, *next).ok());
    }
    EXPECT_TRUE(v.live());
    const auto& c = *v.content();
    if (!c.live_key) return {};
    EXPECT_EQ(c.live_key_hash, std::hash<std::string>{}(*c.live_key));
    return *c.live_key;
  };
  const Edit shift_knee = [](const server::View& v) { return v.edit_shift_root("r_knee"); };
  const Edit shift_other = [](const server::View& v) { return v.edit_shift_root("l_knee"); };
  const Edit split_knee = [](const server::View& v) { return v.edit_split("r_knee"); };
  const Edit onto_walk = [&](const server::View& v) { return v.edit_retarget(walk, {}, {}); };
  const Edit onto_bigger = [&](const server::View& v) { return v.edit_retarget(bigger, {}, {}); };
  const Edit world = [](const server::View& v) { return v.edit_set_roots({"pelvis"}); };

  EXPECT_EQ(key({}), "");
  EXPECT_EQ(key({shift_knee}), key({shift_knee}));
  EXPECT_EQ(key({world, onto_walk}), key({world, onto_walk}));
  const std::vector<std::string> different = {
      key({shift_knee}),
      key({shift_other}),
      key({split_knee}),
      key({onto_walk}),
      key({onto_bigger}),
      key({shift_knee, shift_other}),
      key({shift_other, shift_knee}),
      key({world, onto_walk}),
  };
  for (std::size_t i = 0; i < different.size(); ++i) {
    EXPECT_FALSE(different[i].empty()) << i;
    for (std::size_t k = 0; k < i; ++k) EXPECT_NE(different[i], different[k]) << k << " and " << i;
  }
}

TEST(ViewEdits, TheFloatFormIsCompiledWithTheEditWhenFloatStreamsPlayedTheView) {
  const auto m = long_walk(200);
  const std::string leaf = m->skeleton.joint(static_cast<int>(m->skeleton.size()) - 1).name;
  server::View played(1, "long", m);
  ASSERT_NE(played.content()->compiled->get(), nullptr);  // what a float32 stream does first
  auto edit = played.edit_shift_root(leaf);
  ASSERT_TRUE(edit.ok()) << edit.error().to_string();
  EXPECT_TRUE(edit->compile);
  auto next = edit->run();
  ASSERT_TRUE(next.ok()) << next.error().to_string();
  EXPECT_GT((*next)->compiled->workspace_floats(), 0u) << "compiled by run()";
  ASSERT_TRUE(played.commit(*edit, *next).ok());
  EXPECT_FALSE(played.commit(*edit, *next).ok()) << "an edit made on an older content";

  server::View unplayed(2, "long", m);
  auto lazy = unplayed.edit_shift_root(leaf);
  ASSERT_TRUE(lazy.ok());
  EXPECT_FALSE(lazy->compile);
  auto later = lazy->run();
  ASSERT_TRUE(later.ok());
  EXPECT_EQ((*later)->compiled->workspace_floats(), 0u) << "left for the first float32 stream";
}

}  // namespace
}  // namespace gmr::test
