// RequestHandler without sockets: requests go in as bytes, replies and
// frames come out of a recording Outbox. What a client sees over TCP is
// tested in the other server_*_test files; here the handler alone.
#include "requests/request_handler.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <deque>
#include <limits>
#include <new>
#include <stdexcept>
#include <thread>

#include "gmr/relay/v1/relay.pb.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/framing.h"
#include "gmr/wire/frames.h"
#include "net_test_util.h"
#include "recording_outbox.h"
#include "requests/off_loop.h"
#include "server_parts.h"

namespace gmr::test {
namespace {

// The per-address limit counts an IPv6 host's /64 as one address (before:
// each of its 2^64 addresses had the limit to itself).
TEST(AdmissionLimits, AnIpv6SlashSixtyFourIsOneAddress) {
  server::ServerConfig cfg;
  cfg.max_connections_per_address = 2;
  server::Admission admission(cfg);
  std::vector<std::shared_ptr<RecordingOutbox>> held;
  for (const std::string host : {"2001:db8:1:2::1", "2001:db8:1:2:ffff::9"}) {
    ASSERT_EQ(admission.admit(host), "") << host;
    held.push_back(std::make_shared<RecordingOutbox>(admission.next_id()));
    admission.add(held.back(), {}, host);
  }
  const std::string why = admission.admit("2001:db8:1:2:aaaa:bbbb:cccc:dddd");
  EXPECT_NE(why.find("connections from one address"), std::string::npos) << why;
  EXPECT_EQ(admission.admit("2001:db8:1:3::1"), "") << "another /64 is another host";
  EXPECT_EQ(admission.admit("10.0.0.1"), "");
  admission.remove(held.front()->id());
  EXPECT_EQ(admission.admit("2001:db8:1:2::77"), "") << "a slot of the /64 came free";
}

class RequestHandlerTest : public ::testing::Test {
 protected:
  RequestHandlerTest() : server_(config(), test_library()) {
    spdlog::set_level(spdlog::level::warn);  // the handler logs every hello
    handler_ = std::make_shared<server::RequestHandler>(server_.services, outbox_);
    handler_->start();
  }

  // Every edit computed at once: nothing runs this test's io_context, which
  // answers the edits of long motions (server_edit_test.cpp tests those).
  static server::ServerConfig config() {
    server::ServerConfig cfg;
    cfg.edit_inline_values = std::numeric_limits<std::size_t>::max();
    return cfg;
  }

  // Sends `m` with request id `id` and returns the reply it produced.
  pb::ServerMessage ask(pb::ClientMessage m, std::uint64_t id) {
    m.set_request_id(id);
    handler_->on_message(m.SerializeAsString());
    EXPECT_FALSE(outbox_->replies.empty()) << "no reply";
    if (outbox_->replies.empty()) return {};
    pb::ServerMessage r = outbox_->replies.back();
    outbox_->replies.clear();
    EXPECT_EQ(r.request_id(), id);
    return r;
  }
  pb::ServerMessage hello() {
    pb::ClientMessage m;
    m.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
    return ask(m, 1);
  }
  std::uint32_t create_view(const std::string& motion) {
    pb::ClientMessage m;
    m.mutable_create_view()->set_motion(motion);
    const auto r = ask(m, 2);
    EXPECT_TRUE(r.has_view()) << r.DebugString();
    return r.view().view_id();
  }

  const Motion& walk() const { return *server_.catalog.find("walk").entry->motion; }

  ServerParts server_;
  std::shared_ptr<RecordingOutbox> outbox_ = std::make_shared<RecordingOutbox>();
  std::shared_ptr<server::RequestHandler> handler_;
};

TEST_F(RequestHandlerTest, RefusesEverythingButHelloFirstThenAnswers) {
  pb::ClientMessage list;
  list.mutable_list_motions();
  EXPECT_EQ(ask(list, 5).error().code(), pb::ERROR_CODE_HANDSHAKE_REQUIRED);
  const auto h = hello();
  ASSERT_TRUE(h.has_hello());
  EXPECT_EQ(h.hello().udp_token().size(), 16u);
  EXPECT_NE(h.hello().udp_token(), std::string(16, '\0'));
  const auto r = ask(list, 6);
  ASSERT_TRUE(r.has_motions());
  EXPECT_EQ(static_cast<std::size_t>(r.motions().motions_size()), server_.catalog.library().size());
  handler_->on_message("\xff\xff\xff");  // not a message: an error reply, not an exception
  ASSERT_EQ(outbox_->replies.size(), 1u);
  EXPECT_EQ(outbox_->replies.back().error().code(), pb::ERROR_CODE_BAD_REQUEST);
}

// Before, a second Hello re-evaluated the role while what the first one
// opened (a publication, subscriptions) went on. The role is settled once.
TEST_F(RequestHandlerTest, ASecondHelloIsRefusedAndTheFirstRoleStays) {
  ASSERT_TRUE(hello().has_hello());
  create_view("walk");
  pb::ClientMessage again;
  again.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
  again.mutable_hello()->set_auth_token("another-token-0123456789abcdef");
  const auto r = ask(again, 3);
  EXPECT_EQ(r.error().code(), pb::ERROR_CODE_BAD_REQUEST) << r.DebugString();
  EXPECT_NE(r.error().message().find("Hello was already said on this connection (as 'control')"), std::string::npos)
      << r.error().message();
  pb::ClientMessage list;
  list.mutable_list_motions();
  EXPECT_TRUE(ask(list, 4).has_motions()) << "the connection goes on";
}

TEST_F(RequestHandlerTest, LibraryErrorsBecomeProtocolCodesWithoutPrechecks) {
  hello();
  const std::uint32_t v = create_view("walk");
  pb::ClientMessage shift;
  shift.mutable_shift_root()->set_view_id(v);
  shift.mutable_shift_root()->set_joint("no_such_joint");
  auto r = ask(shift, 10);
  EXPECT_EQ(r.error().code(), pb::ERROR_CODE_NOT_FOUND) << r.DebugString();
  EXPECT_NE(r.error().message().find("no_such_joint"), std::string::npos);

  const std::string root = walk().skeleton.joint(0).name;
  pb::ClientMessage split;
  split.mutable_split()->set_view_id(v);
  split.mutable_split()->set_joint(root);
  EXPECT_EQ(ask(split, 11).error().code(), pb::ERROR_CODE_FAILED_PRECONDITION);

  pb::ClientMessage roots;
  roots.mutable_set_roots()->set_view_id(v);
  EXPECT_EQ(ask(roots, 12).error().code(), pb::ERROR_CODE_BAD_REQUEST);
  roots.mutable_set_roots()->add_roots(root);
  roots.mutable_set_roots()->add_roots(root);
  EXPECT_EQ(ask(roots, 13).error().code(), pb::ERROR_CODE_FAILED_PRECONDITION);  // listed twice

  pb::ClientMessage other_view = shift;
  other_view.mutable_shift_root()->set_view_id(v + 100);
  EXPECT_EQ(ask(other_view, 14).error().code(), pb::ERROR_CODE_NOT_FOUND);
}

// A subscription's frames come out of the outbox as whole ServerMessages,
// then the end notice with the count.
TEST_F(RequestHandlerTest, SubscriptionFramesGoToTheOutboxThenItEnds) {
  hello();
  const std::uint32_t v = create_view("walk");
  pb::ClientMessage sub;
  sub.mutable_subscribe()->set_view_id(v);
  sub.mutable_subscribe()->set_rate_hz(1000);
  sub.mutable_subscribe()->set_max_frames(5);
  const auto r = ask(sub, 20);
  ASSERT_TRUE(r.has_subscribed()) << r.DebugString();
  const std::uint32_t id = r.subscribed().subscription_id();
  // Run the server's loop until the subscription has ended (a bounded wait).
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (outbox_->replies.empty() && std::chrono::steady_clock::now() < deadline) {
    server_.io.run_for(std::chrono::milliseconds(20));
  }
  ASSERT_EQ(outbox_->frames.size(), 5u);
  for (std::size_t i = 0; i < outbox_->frames.size(); ++i) {
    const auto& f = outbox_->frames[i];
    ASSERT_TRUE(f.has_frame());
    EXPECT_EQ(f.frame().subscription_id(), id);
    EXPECT_EQ(f.frame().view_id(), v);
    EXPECT_EQ(f.frame().sequence(), i);
    auto values = wire::decode_frame(f.frame());
    ASSERT_TRUE(values.ok()) << values.error().to_string();
    EXPECT_EQ(values->positions.size(), walk().skeleton.size());
    EXPECT_EQ(outbox_->keys[i], id);
  }
  ASSERT_EQ(outbox_->replies.size(), 1u);
  const auto& end = outbox_->replies.front();
  ASSERT_TRUE(end.has_subscription_ended());
  EXPECT_EQ(end.subscription_ended().frames_sent(), 5u);
  EXPECT_EQ(end.subscription_ended().reason(), "max_frames reached");
}

// A subscriber joining a running live source starts at its newest frame,
// handed over after the reply. Before, a frame published between the reply
// and that hand-over reached the subscriber twice (once in its fan-out, once
// as "the newest"), and a recording of the source had the frame twice (seen
// under TSan's timing in CliNet.PublishPlaysAFileLiveAndRecordCapturesItsPositions).
TEST_F(RequestHandlerTest, AJoinerOfALiveSourceGetsEachFrameOnceWhenOneCrossesItsFirst) {
  const Motion& m = walk();
  auto source = server_.catalog.add_live("live/walk", m.skeleton, 1.0 / 60, 0.01);
  ASSERT_NE(source, nullptr);
  ASSERT_TRUE(source->push(m.frame(0), std::nullopt, server::Clock::now()).ok());
  hello();
  const std::uint32_t v = create_view("live/walk");
  pb::ClientMessage sub;
  sub.mutable_subscribe()->set_view_id(v);
  sub.mutable_subscribe()->set_rate_hz(60);
  ASSERT_TRUE(ask(sub, 20).has_subscribed());
  // Frame 1 arrives before the loop hands the joiner its newest frame.
  ASSERT_TRUE(source->push(m.frame(1), std::nullopt, server::Clock::now()).ok());
  server_.io.restart();
  server_.io.poll();
  ASSERT_TRUE(source->push(m.frame(2), std::nullopt, server::Clock::now()).ok());
  server_.io.restart();
  server_.io.poll();
  ASSERT_EQ(outbox_->frames.size(), 2u) << "frames 1 and 2, each once";
  std::vector<std::vector<Eigen::Vector3d>> positions;
  for (std::size_t i = 0; i < 2; ++i) {
    const auto& f = outbox_->frames[i].frame();
    EXPECT_EQ(f.frame_index(), i + 1);
    EXPECT_EQ(f.sequence(), i) << "no gap: the duplicate was never a frame";
    auto values = wire::decode_frame(f);
    ASSERT_TRUE(values.ok()) << values.error().to_string();
    positions.push_back(values->positions);
  }
  double moved = 0;
  for (std::size_t j = 0; j < positions[0].size(); ++j) moved += (positions[1][j] - positions[0][j]).norm();
  EXPECT_GT(moved, 0.0) << "two different frames of the walk";
}

TEST_F(RequestHandlerTest, AnotherProtocolVersionClosesAfterTheReply) {
  pb::ClientMessage m;
  m.mutable_hello()->set_protocol_version(wire::kProtocolVersion + 1);
  EXPECT_EQ(ask(m, 1).error().code(), pb::ERROR_CODE_VERSION_MISMATCH);
  EXPECT_TRUE(outbox_->closing());
}

// Another replica's announces over NATS get the checks a client's Publish
// gets (the same function): a bad name, no joints, a rate out of range or a
// negative unit is refused and counted, and at most max_remote_sources are
// tracked. A valid one is served, and its frames are checked as published
// frames are.
TEST_F(RequestHandlerTest, RelayedAnnouncesAreCheckedAsPublishesAreAndBounded) {
  server_.cfg.max_remote_sources = 4;
  const Motion& m = walk();
  pb::Publish good;
  good.set_name("remote/walk");
  wire::to_proto(m.skeleton, *good.mutable_skeleton());
  good.set_frame_time(1.0 / 60);
  good.set_metres_per_unit(0.01);
  std::uint64_t serial = 0;
  auto announce = [&](const pb::Publish& p, const std::string& origin) {
    gmr::relay::v1::LiveRelay r;
    r.set_origin(origin);
    r.set_serial(++serial);
    *r.mutable_announce() = p;
    server_.replicas.on_relay(r);
    return serial;
  };

  std::vector<pb::Publish> bad(4, good);
  bad[0].set_name("bad\nname");
  bad[1].mutable_skeleton()->clear_joints();
  bad[2].set_frame_time(1e-9);  // 1 GHz
  bad[3].set_metres_per_unit(-1);
  for (std::size_t i = 0; i < bad.size(); ++i) {
    bad[i].set_name(bad[i].name() + std::to_string(i));
    announce(bad[i], "replica-a");
    EXPECT_FALSE(server_.catalog.live_sources().contains(bad[i].name())) << i;
    EXPECT_EQ(server_.replicas.announces_refused(), i + 1);
  }
  // Refusing a publish from a client says the same.
  server_.cfg.anonymous = server::Role::kPublish;
  hello();
  pb::ClientMessage publish;
  *publish.mutable_publish() = bad[2];
  const auto refused = ask(publish, 30);
  EXPECT_EQ(refused.error().code(), pb::ERROR_CODE_BAD_REQUEST);
  EXPECT_NE(refused.error().message().find("frame time 1e-09 s: the rate must be within [0.01, 10000] Hz"),
            std::string::npos)
      << refused.DebugString();

  // Four tracked (the refused ones count until they time out): the next is refused.
  EXPECT_EQ(server_.replicas.remote_sources(), 4u);
  announce(good, "replica-b");
  EXPECT_FALSE(server_.catalog.live_sources().contains("remote/walk"));
  EXPECT_EQ(server_.replicas.announces_refused(), 5u);

  // With room, it is served; a frame of the wrong size is refused, a right one accepted.
  server_.cfg.max_remote_sources = 5;
  const std::uint64_t s = announce(good, "replica-b");
  ASSERT_TRUE(server_.catalog.live_sources().contains("remote/walk"));
  EXPECT_EQ(server_.catalog.live_sources().at("remote/walk")->origin(), "replica-b");
  gmr::relay::v1::LiveRelay frame;
  frame.set_origin("replica-b");
  frame.set_serial(s);
  frame.mutable_frame()->set_index(0);
  frame.mutable_frame()->add_values(1.0);
  server_.replicas.on_relay(frame);
  EXPECT_EQ(server_.catalog.live_frames_refused(), 1u);
  frame.mutable_frame()->clear_values();
  for (double v : m.frame(0)) frame.mutable_frame()->add_values(v);
  server_.replicas.on_relay(frame);
  EXPECT_EQ(server_.catalog.live_frames_received(), 1u);
  EXPECT_EQ(server_.catalog.live_sources().at("remote/walk")->frames(), 1u);
  // A replica that joins a running source takes its first frame's number
  // as it comes (a source may be hours in).
  server_.cfg.max_remote_sources = 6;
  pb::Publish late = good;
  late.set_name("remote/late");
  const std::uint64_t late_serial = announce(late, "replica-b");
  gmr::relay::v1::LiveRelay first = frame;
  first.set_serial(late_serial);
  first.mutable_frame()->set_index(10'000'000);
  server_.replicas.on_relay(first);
  ASSERT_TRUE(server_.catalog.live_sources().contains("remote/late"));
  EXPECT_EQ(server_.catalog.live_sources().at("remote/late")->frames(), 10'000'001u);
  EXPECT_EQ(server_.catalog.live_frames_received(), 2u);
  // After it, an index far ahead would freeze the source (every later frame
  // "came after" it): refused, as are values that are not finite.
  frame.mutable_frame()->set_index(std::numeric_limits<std::uint64_t>::max() - 1);
  server_.replicas.on_relay(frame);
  frame.mutable_frame()->set_index(1);
  frame.mutable_frame()->set_values(0, std::numeric_limits<double>::infinity());
  server_.replicas.on_relay(frame);
  EXPECT_EQ(server_.catalog.live_frames_refused(), 3u);
  frame.mutable_frame()->set_values(0, 0.0);
  server_.replicas.on_relay(frame);
  EXPECT_EQ(server_.catalog.live_sources().at("remote/walk")->frames(), 2u);
  auto source = server_.catalog.live_sources().at("remote/walk");
  gmr::relay::v1::LiveRelay end;
  end.set_origin("replica-b");
  end.set_serial(s);
  end.set_end("bye\x1b[2J");
  server_.replicas.on_relay(end);
  EXPECT_TRUE(source->ended());
  EXPECT_FALSE(server_.catalog.live_sources().contains("remote/walk"));
}

// Work taken off the control loop (long edits, marker calibrations): its
// outcome comes back on the loop's thread, and nothing it throws escapes the
// pool's thread: running out of memory and any other exception become errors
// that say what was being done.
TEST(OffLoop, TheOutcomeComesBackOnTheLoopAndThrowsBecomeErrors) {
  server::net::io_context io;
  server::net::thread_pool pool(1);
  std::vector<Result<int>> outcomes;
  std::vector<std::thread::id> where;
  auto done = [&](Result<int> r) {
    outcomes.push_back(std::move(r));
    where.push_back(std::this_thread::get_id());
  };
  server::run_off_loop<int>(
      pool, io, "the sum", [] { return Result<int>(42); }, done);
  server::run_off_loop<int>(
      pool, io, "the sum", []() -> Result<int> { throw std::runtime_error("a bad part"); }, done);
  server::run_off_loop<int>(
      pool, io, "the sum", []() -> Result<int> { throw std::bad_alloc(); }, done);
  pool.join();  // the three outcomes are posted to io, which nothing has run yet
  EXPECT_TRUE(outcomes.empty()) << "an outcome ran off the loop";
  io.run();
  ASSERT_EQ(outcomes.size(), 3u);
  ASSERT_TRUE(outcomes[0].ok());
  EXPECT_EQ(*outcomes[0], 42);
  ASSERT_FALSE(outcomes[1].ok());
  EXPECT_EQ(outcomes[1].error().kind, ErrorKind::kFailedPrecondition);
  EXPECT_EQ(outcomes[1].error().message, "the sum failed: a bad part");
  ASSERT_FALSE(outcomes[2].ok());
  EXPECT_EQ(outcomes[2].error().kind, ErrorKind::kResourceExhausted);
  EXPECT_EQ(outcomes[2].error().message, "the server ran out of memory computing the sum");
  for (const auto& id : where) EXPECT_EQ(id, std::this_thread::get_id()) << "the loop's thread";
}

}  // namespace
}  // namespace gmr::test
