// What the server does with bad input: every bad request gets an Error reply
// with a code, malformed framing closes only that connection, UDP datagrams
// without a valid session token are ignored. After each, the server still
// serves a fresh client.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <atomic>
#include <cstring>
#include <sstream>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "gmr/wire/framing.h"
#include "gmr/wire/udp.h"
#include "net_test_util.h"

namespace gmr::test {
namespace {

// A fresh client can still list motions.
void expect_server_alive(TestServer& s) {
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto list = c->list_motions();
  ASSERT_TRUE(list.ok()) << list.error().to_string();
  EXPECT_FALSE(list->empty());
}

pb::ErrorCode error_of(const std::optional<pb::ServerMessage>& m) {
  EXPECT_TRUE(m.has_value()) << "no reply";
  if (!m) return pb::ERROR_CODE_UNSPECIFIED;
  EXPECT_TRUE(m->has_error()) << m->DebugString();
  EXPECT_FALSE(m->error().message().empty());
  return m->error().code();
}

TEST(BadInput, GarbageBytesCloseOnlyThatConnection) {
  TestServer s;
  RawConnection good(s.port());
  good.handshake();
  RawConnection bad(s.port());
  bad.send_bytes("GET / HTTP/1.1\r\nHost: x\r\n\r\n");  // "GET " is a length of ~1.2 GB
  EXPECT_TRUE(bad.wait_closed());
  auto m = request(5);
  m.mutable_list_motions();
  good.send(m);
  auto r = good.reply();
  ASSERT_TRUE(r && r->has_motions());
  EXPECT_EQ(r->request_id(), 5u);
  expect_server_alive(s);
}

TEST(BadInput, OversizedLengthPrefixClosesTheConnection) {
  server::ServerConfig cfg;
  cfg.max_message_bytes = 4096;
  TestServer s(cfg);
  RawConnection c(s.port());
  c.handshake();
  c.send_bytes(std::string("\x00\x00\x10\x01", 4));  // 4097 bytes announced
  EXPECT_TRUE(c.wait_closed());
  expect_server_alive(s);
}

TEST(BadInput, TruncatedLengthPrefixThenCloseIsHandled) {
  TestServer s;
  RawConnection c(s.port());
  c.send_bytes(std::string("\x00\x00", 2));
  c.shutdown_send();
  EXPECT_TRUE(c.wait_closed());
  expect_server_alive(s);
}

TEST(BadInput, TruncatedMessageIsClosedByTheIdleTimeout) {
  server::ServerConfig cfg;
  cfg.idle_timeout = std::chrono::milliseconds(200);
  TestServer s(cfg);
  RawConnection c(s.port());
  c.send_bytes(
      std::string("\x00\x00\x00\x20"
                  "abc",
                  7));  // 32 announced, 3 sent, then silence
  EXPECT_TRUE(c.wait_closed(std::chrono::seconds(10)));
  expect_server_alive(s);
}

// The log names how much of a cut-off message arrived (it once printed 0).
TEST(BadInput, TruncatedMessageLogNamesTheBytesReceived) {
  std::ostringstream log;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  const auto previous = spdlog::default_logger();
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("capture", sink));
  {
    TestServer s;
    RawConnection c(s.port());
    c.send_bytes(
        std::string("\x00\x00\x00\x20"
                    "abc",
                    7));  // 32 announced, 3 sent, then the end
    c.shutdown_send();
    EXPECT_TRUE(c.wait_closed());
    expect_server_alive(s);
  }  // the server stops: everything it logged is in
  spdlog::set_default_logger(previous);
  EXPECT_THAT(log.str(), ::testing::HasSubstr("truncated message: 3 of 32 bytes announced; closing"));
}

// Client text cannot forge a log line, drive a terminal or flood the log.
TEST(BadInput, ClientTextIsEscapedAndBadRequestsCannotFloodTheLog) {
  std::ostringstream log;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(log);
  const auto previous = spdlog::default_logger();
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("capture", sink));
  const std::string forged = "evil\n2026-11-23T07:00:00.000 info conn 99: hello from 'admin'\x1b[31m";
  {
    TestServer s;
    spdlog::set_level(spdlog::level::info);
    RawConnection c(s.port());
    pb::ClientMessage hello = request(1);
    hello.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
    hello.mutable_hello()->set_client_name(forged + std::string(1 << 20, 'x'));
    c.send(hello);
    ASSERT_TRUE(c.reply().has_value());
    // 1,000 bad requests (about 1 MB) in a burst.
    for (int i = 0; i < 1000; ++i) c.send_bytes(wire::frame_bytes(std::string(1000, '\xff')));
    for (int i = 0; i < 1000; ++i) ASSERT_EQ(error_of(c.reply()), pb::ERROR_CODE_BAD_REQUEST);
  }  // the server stops: everything it logged is in
  spdlog::set_level(spdlog::level::warn);
  spdlog::set_default_logger(previous);
  const std::string text = log.str();
  // One line per event: no line starts with the forged timestamp, no escape byte.
  EXPECT_EQ(text.find("\n2026-11-23T07:00:00.000"), std::string::npos) << text;
  EXPECT_EQ(text.find('\x1b'), std::string::npos);
  EXPECT_THAT(text, ::testing::HasSubstr("hello from \"evil\\n2026-11-23T07:00:00.000 info conn 99: hello from "
                                         "'admin'\\x1b[3\" (and 1048578 more bytes)"));
  // The flood: a few lines, then one that counts the rest.
  std::size_t not_a_message = 0;
  for (std::size_t p = 0; (p = text.find("is not a ClientMessage", p)) != std::string::npos; ++p) ++not_a_message;
  EXPECT_LE(not_a_message, 10u);
  EXPECT_THAT(text, ::testing::HasSubstr("lines about its requests were suppressed"));
  EXPECT_LT(text.size(), 16u * 1024) << "1 MB of bad requests once wrote 16 MB of log";
}

TEST(BadInput, WellFramedGarbageGetsAnErrorAndTheConnectionStays) {
  TestServer s;
  RawConnection c(s.port());
  c.handshake();
  c.send_bytes(wire::frame_bytes("\xff\xff\xff\xff\xff\xff\xff"));
  EXPECT_EQ(error_of(c.reply()), pb::ERROR_CODE_BAD_REQUEST);
  auto m = request(9);
  m.mutable_list_motions();
  c.send(m);
  auto r = c.reply();
  ASSERT_TRUE(r && r->has_motions());
}

TEST(BadInput, UnknownMessageTypeGetsUnknownRequest) {
  TestServer s;
  RawConnection c(s.port());
  c.handshake();
  // request_id 3 and a field 99 (a body from a newer protocol).
  std::string bytes = "\x08\x03";
  bytes += "\x9a\x06\x02\x08\x01";  // field 99, length-delimited, 2 bytes
  c.send_bytes(wire::frame_bytes(bytes));
  auto r = c.reply();
  EXPECT_EQ(error_of(r), pb::ERROR_CODE_UNKNOWN_REQUEST);
  EXPECT_EQ(r->request_id(), 3u);
  // An empty message (length 0) is the same.
  c.send_bytes(std::string(4, '\0'));
  EXPECT_EQ(error_of(c.reply()), pb::ERROR_CODE_UNKNOWN_REQUEST);
}

TEST(BadInput, RequestsBeforeHelloAreRefused) {
  TestServer s;
  RawConnection c(s.port());
  auto m = request(2);
  m.mutable_list_motions();
  c.send(m);
  EXPECT_EQ(error_of(c.reply()), pb::ERROR_CODE_HANDSHAKE_REQUIRED);
}

TEST(BadInput, IncompatibleProtocolVersionIsRefusedClearly) {
  TestServer s;
  RawConnection c(s.port());
  auto m = request(1);
  m.mutable_hello()->set_protocol_version(wire::kProtocolVersion + 1);
  c.send(m);
  auto r = c.reply();
  EXPECT_EQ(error_of(r), pb::ERROR_CODE_VERSION_MISMATCH);
  EXPECT_NE(r->error().message().find("version " + std::to_string(wire::kProtocolVersion)), std::string::npos)
      << r->error().message();
  EXPECT_TRUE(c.wait_closed());
}

TEST(BadInput, UnknownMotionViewJointAndSubscription) {
  TestServer s;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto expect_code = [](const Error& e, const std::string& code, const std::string& what) {
    EXPECT_EQ(e.message.rfind(code, 0), 0u) << e.message;
    EXPECT_NE(e.message.find(what), std::string::npos) << e.message;
  };
  auto sk = c->skeleton("no_such_motion");
  ASSERT_FALSE(sk.ok());
  expect_code(sk.error(), "NOT_FOUND", "no_such_motion");
  auto v0 = c->create_view("no_such_motion");
  ASSERT_FALSE(v0.ok());
  expect_code(v0.error(), "NOT_FOUND", "no_such_motion");
  auto q = c->query(77, 0, 1);
  ASSERT_FALSE(q.ok());
  expect_code(q.error(), "NOT_FOUND", "view 77");
  auto v = c->create_view("walk");
  ASSERT_TRUE(v.ok());
  for (auto r : {c->shift_root(v->id, "tail"), c->split(v->id, "tail"), c->join(v->id, "tail"),
                 c->set_roots(v->id, {"pelvis", "tail"}), c->set_coordinates(v->id, "tail")}) {
    ASSERT_FALSE(r.ok());
    expect_code(r.error(), "NOT_FOUND", "'tail'");
  }
  auto q2 = c->query(v->id, 0, 1, false, {"tail"});
  ASSERT_FALSE(q2.ok());
  expect_code(q2.error(), "NOT_FOUND", "'tail'");
  client::SubscribeOptions tail;
  tail.joints = {"tail"};
  auto sub = c->subscribe(v->id, tail, [](const auto&) {});
  ASSERT_FALSE(sub.ok());
  expect_code(sub.error(), "NOT_FOUND", "'tail'");
  for (auto st : {c->unsubscribe(41), c->pause(41), c->resume(41), c->seek(41, 0)}) {
    ASSERT_FALSE(st.ok());
    expect_code(st.error(), "NOT_FOUND", "subscription 41");
  }
}

TEST(BadInput, ImpossibleOperationsAreRefusedAndLeaveTheViewAsItWas) {
  TestServer s;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("walk");
  ASSERT_TRUE(v.ok());
  auto expect_refused = [&](const Result<client::ViewState>& r, const std::string& code) {
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message.rfind(code, 0), 0u) << r.error().message;
  };
  expect_refused(c->join(v->id, "pelvis"), "FAILED_PRECONDITION");   // the last root
  expect_refused(c->join(v->id, "l_knee"), "FAILED_PRECONDITION");   // not a root
  expect_refused(c->split(v->id, "pelvis"), "FAILED_PRECONDITION");  // already a root
  expect_refused(c->set_roots(v->id, {}), "BAD_REQUEST");
  expect_refused(c->set_roots(v->id, {"head", "head"}), "FAILED_PRECONDITION");
  auto after = c->query(v->id, 0, 1);
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(after->skeleton_version, v->skeleton_version);  // nothing changed
  // Frame ranges and stream parameters.
  auto q = c->query(v->id, 5, 3);
  ASSERT_FALSE(q.ok());
  EXPECT_EQ(q.error().message.rfind("BAD_REQUEST", 0), 0u) << q.error().message;
  auto q2 = c->query(v->id, 0, static_cast<std::uint32_t>(v->frame_count + 1));
  ASSERT_FALSE(q2.ok());
  for (int k = 0; k < 3; ++k) {
    client::SubscribeOptions o;
    if (k == 0) o.start_frame = 100000;
    if (k == 1) o.speed = -1.0;
    if (k == 2) o.rate_hz = 1e9;
    auto r = c->subscribe(v->id, o, [](const auto&) {});
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().message.rfind("BAD_REQUEST", 0), 0u) << r.error().message;
  }
}

TEST(BadInput, QueryAboveTheMessageLimitIsRefusedBeforeComputing) {
  server::ServerConfig cfg;
  cfg.max_message_bytes = 8192;
  TestServer s(cfg);
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("walk");
  ASSERT_TRUE(v.ok());
  auto q = c->query(v->id, 0, static_cast<std::uint32_t>(v->frame_count), true);
  ASSERT_FALSE(q.ok());
  EXPECT_EQ(q.error().message.rfind("RESOURCE_EXHAUSTED", 0), 0u) << q.error().message;
  EXPECT_TRUE(c->query(v->id, 0, 2).ok());
}

TEST(BadInput, ViewAndConnectionLimits) {
  server::ServerConfig cfg;
  cfg.max_views_per_connection = 2;
  cfg.max_connections = 1;
  TestServer s(cfg);
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  EXPECT_TRUE(c->create_view("walk").ok());
  EXPECT_TRUE(c->create_view("walk").ok());
  auto third = c->create_view("walk");
  ASSERT_FALSE(third.ok());
  EXPECT_EQ(third.error().message.rfind("RESOURCE_EXHAUSTED", 0), 0u) << third.error().message;
  // A second connection is told why and closed.
  RawConnection second(s.port());
  auto r = second.receive();
  EXPECT_EQ(error_of(r), pb::ERROR_CODE_RESOURCE_EXHAUSTED);
  EXPECT_TRUE(second.wait_closed());
  EXPECT_TRUE(c->list_motions().ok());
}

// proto3 keeps enum values it does not know; the server refuses them.
TEST(BadInput, UnknownTransportOrPrecisionIsABadRequest) {
  TestServer s;
  RawConnection c(s.port());
  c.handshake();
  const auto view = c.create_view(2, "walk");
  ASSERT_TRUE(view);
  for (const auto& [transport, precision] : {std::pair{7, 0}, std::pair{0, 9}, std::pair{-1, 0}}) {
    auto m = request(3);
    m.mutable_subscribe()->set_view_id(*view);
    m.mutable_subscribe()->set_transport(static_cast<pb::Transport>(transport));
    m.mutable_subscribe()->set_precision(static_cast<pb::Precision>(precision));
    c.send(m);
    const auto r = c.reply();
    EXPECT_EQ(error_of(r), pb::ERROR_CODE_BAD_REQUEST) << transport << " " << precision;
    if (r) {
      EXPECT_NE(r->error().message().find("unknown transport"), std::string::npos) << r->error().message();
    }
  }
}

// A UDP socket on loopback with a receive deadline.
struct UdpSocket {
  int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
  sockaddr_in server{};
  explicit UdpSocket(std::uint16_t port) {
    server.sin_family = AF_INET;
    server.sin_port = htons(port);
    server.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    timeval tv{0, 300 * 1000};
    ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  }
  ~UdpSocket() { ::close(fd); }
  void send(const std::string& d) {
    ::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<sockaddr*>(&server), sizeof server);
  }
  // Every datagram that arrives within `window`.
  std::vector<std::string> receive_for(std::chrono::milliseconds window) {
    std::vector<std::string> got;
    const auto until = std::chrono::steady_clock::now() + window;
    char buf[2048];
    while (std::chrono::steady_clock::now() < until) {
      const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
      if (n >= 0) got.emplace_back(buf, static_cast<std::size_t>(n));
    }
    return got;
  }
};

wire::UdpToken token_of(const client::Client& c) {
  wire::UdpToken t;
  std::copy(c.hello().udp_token.begin(), c.hello().udp_token.end(), t.begin());
  return t;
}

TEST(BadInput, UdpDatagramsWithWrongTokensAreIgnored) {
  TestServer s;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  const wire::UdpToken token = token_of(*c);
  wire::UdpToken off_by_one_bit = token;
  off_by_one_bit[15] ^= 1;
  UdpSocket u(s.server.udp_port());
  std::string v1(16, '\0');  // a version 1 registration (8-byte token)
  std::memcpy(v1.data(), "GMRU\x01\x01\0\0", 8);
  for (const std::string& d :
       {wire::make_register_datagram(off_by_one_bit), wire::make_register_datagram({}), std::string("garbage"),
        wire::make_register_datagram(token).substr(0, 12), v1, wire::make_confirm_datagram(token, {})}) {
    u.send(d);
  }
  // Nothing comes back to any of them: not even a challenge.
  EXPECT_TRUE(u.receive_for(std::chrono::milliseconds(300)).empty());
  server::ServerStats st = s.server.stats();
  EXPECT_EQ(st.udp_rejected, 6u);
  EXPECT_EQ(st.udp_challenges, 0u);
  ASSERT_EQ(st.sessions.size(), 1u);
  EXPECT_FALSE(st.sessions[0].udp_registered);
  // Without a registration a UDP subscription is refused with the reason.
  pb::ClientMessage m;
  auto v = c->create_view("walk");
  ASSERT_TRUE(v.ok());
  m.mutable_subscribe()->set_view_id(v->id);
  m.mutable_subscribe()->set_transport(pb::TRANSPORT_UDP);
  auto r = c->request_raw(m.SerializeAsString());
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  pb::ServerMessage reply;
  ASSERT_TRUE(reply.ParseFromString(*r));
  EXPECT_EQ(error_of(reply), pb::ERROR_CODE_FAILED_PRECONDITION);
  // The right token gets one challenge, the size of the registration; the
  // echo from the same socket registers it, and only it.
  u.send(wire::make_register_datagram(token));
  const auto got = u.receive_for(std::chrono::milliseconds(300));
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].size(), wire::kRegisterBytes);
  const auto cookie = wire::parse_challenge_datagram(got[0]);
  ASSERT_TRUE(cookie.has_value());
  EXPECT_FALSE(s.server.stats().sessions[0].udp_registered);
  u.send(wire::make_confirm_datagram(token, *cookie));
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  do {
    st = s.server.stats();
  } while (!st.sessions[0].udp_registered && std::chrono::steady_clock::now() < deadline);
  EXPECT_TRUE(st.sessions[0].udp_registered);
}

// The reflection attack: a registration whose source address is forged (here:
// sent from the victim's own socket, which never confirms) makes the server
// send the victim one challenge of at most the registration's size per
// registration datagram, and never a frame, while the session's real
// endpoint keeps streaming.
TEST(BadInput, AForgedRegistrationGetsOneSmallChallengeAndNoFrames) {
  TestServer s;
  std::atomic<int> frames{0};  // outlives the client, whose thread counts into it
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto v = c->create_view("walk");
  ASSERT_TRUE(v.ok());
  client::SubscribeOptions o;
  o.udp = true;
  o.loop = true;
  o.rate_hz = 500;
  ASSERT_TRUE(c->subscribe(
                   v->id, o, [&](const client::ReceivedFrame&) { ++frames; }, nullptr)
                  .ok());

  UdpSocket victim(s.server.udp_port());
  const std::string forged = wire::make_register_datagram(token_of(*c));  // the worst case: the token leaked
  for (int i = 0; i < 5; ++i) victim.send(forged);
  const int before = frames.load();
  const auto got = victim.receive_for(std::chrono::milliseconds(600));
  std::size_t bytes = 0;
  for (const auto& d : got) {
    EXPECT_TRUE(wire::parse_challenge_datagram(d).has_value()) << "the victim got something other than a challenge";
    bytes += d.size();
  }
  EXPECT_EQ(got.size(), 5u);
  EXPECT_LE(bytes, 5 * forged.size()) << "amplification above 1";
  EXPECT_GT(frames.load(), before) << "the real endpoint keeps its frames";
  EXPECT_TRUE(s.server.stats().sessions[0].udp_registered);
}

}  // namespace
}  // namespace gmr::test
