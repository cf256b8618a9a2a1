// gmr-server's HTTP port (docs/viewer.md, docs/operations.md): files, health
// and readiness, and the WebSocket, which carries the TCP protocol's requests
// and replies (binary, or protobuf's JSON mapping) under the same limits and
// admission. A Boost.Beast client on 127.0.0.1; reads have deadlines.
#include <gtest/gtest.h>

#include <google/protobuf/util/json_util.h>
#include <sys/socket.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <filesystem>
#include <fstream>
#include <thread>

#include <google/protobuf/util/message_differencer.h>

#include <cmath>
#include <limits>

#include "gmr/wire/framing.h"
#include "net_test_util.h"
#include "transport/ws_connection.h"
#include "transport/ws_json.h"

namespace gmr::test {
namespace {

namespace net = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = net::ip::tcp;

// Reads on `s` fail after `timeout` instead of blocking.
void read_deadline(tcp::socket& s, std::chrono::milliseconds timeout) {
  timeval tv{static_cast<time_t>(timeout.count() / 1000), static_cast<suseconds_t>((timeout.count() % 1000) * 1000)};
  ::setsockopt(s.native_handle(), SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
}

struct HttpReply {
  unsigned status = 0;
  std::string body;
  std::string content_type;
  std::string content_length;
};

// One request on a fresh connection; `raw` is sent as it is when given.
// `from`: the local address to connect from (127.0.0.x stand for hosts).
HttpReply http_request(std::uint16_t port, http::verb verb, const std::string& target, const std::string& raw = {},
                       const std::string& from = {}) {
  net::io_context io;
  tcp::socket s(io);
  if (!from.empty()) {
    s.open(tcp::v4());
    s.bind(tcp::endpoint(net::ip::make_address(from), 0));
  }
  s.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
  read_deadline(s, std::chrono::seconds(5));
  if (raw.empty()) {
    http::request<http::empty_body> req{verb, target, 11};
    req.set(http::field::host, "127.0.0.1");
    http::write(s, req);
  } else {
    net::write(s, net::buffer(raw));
  }
  beast::flat_buffer buf;
  http::response_parser<http::string_body> parser;
  parser.skip(verb == http::verb::head);
  parser.body_limit(16 << 20);
  beast::error_code ec;
  http::read(s, buf, parser, ec);
  if (ec) return {};
  const auto& res = parser.get();
  return {res.result_int(), res.body(), std::string(res[http::field::content_type]),
          std::string(res[http::field::content_length])};
}

HttpReply get(std::uint16_t port, const std::string& target) { return http_request(port, http::verb::get, target); }

// The server's answer to a WebSocket upgrade of /ws that it refuses (a
// status other than 101), with the subprotocol and Origin given.
HttpReply refused_upgrade(std::uint16_t port, const std::string& protocol, const std::string& origin = {},
                          const std::string& host = "127.0.0.1") {
  std::string raw = "GET /ws HTTP/1.1\r\nHost: " + host + ":" + std::to_string(port) +
                    "\r\nConnection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\n"
                    "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
  if (!protocol.empty()) raw += "Sec-WebSocket-Protocol: " + protocol + "\r\n";
  if (!origin.empty()) raw += "Origin: " + origin + "\r\n";
  return http_request(port, http::verb::get, "/ws", raw + "\r\n");
}

// A WebSocket client of /ws.
class WsClient {
 public:
  // `protocol` empty: none asked for. `origin` empty: none sent.
  // `host`: the Host header (default 127.0.0.1:port).
  WsClient(std::uint16_t port, const std::string& protocol, const std::string& origin = {}, std::string host = {})
      : ws_(io_) {
    if (host.empty()) host = "127.0.0.1:" + std::to_string(port);
    ws_.next_layer().connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
    read_deadline(ws_.next_layer(), std::chrono::seconds(5));
    ws_.set_option(websocket::stream_base::decorator([protocol, origin](websocket::request_type& req) {
      if (!protocol.empty()) req.set(http::field::sec_websocket_protocol, protocol);
      if (!origin.empty()) req.set(http::field::origin, origin);
    }));
    ws_.handshake(response_, host, "/ws", error_);
  }
  bool open() const { return !error_; }
  std::string chosen_protocol() const { return std::string(response_[http::field::sec_websocket_protocol]); }

  void send(const pb::ClientMessage& m) {
    ws_.binary(true);
    ws_.write(net::buffer(m.SerializeAsString()));
  }
  void send_text(const std::string& text) {
    ws_.text(true);
    ws_.write(net::buffer(text));
  }
  void send_bytes(const std::string& bytes) {
    ws_.binary(true);
    beast::error_code ec;
    ws_.write(net::buffer(bytes), ec);
  }
  // The next message as text (JSON) or bytes; nothing when closed or late.
  std::optional<std::string> receive_raw(bool* text = nullptr) {
    beast::flat_buffer buf;
    beast::error_code ec;
    ws_.read(buf, ec);
    if (ec) {
      closed_ = true;
      return std::nullopt;
    }
    if (text) *text = ws_.got_text();
    return beast::buffers_to_string(buf.data());
  }
  std::optional<pb::ServerMessage> receive() {
    auto bytes = receive_raw();
    if (!bytes) return std::nullopt;
    pb::ServerMessage m;
    EXPECT_TRUE(m.ParseFromString(*bytes));
    return m;
  }
  // The next message that is not a pushed frame or heartbeat.
  std::optional<pb::ServerMessage> reply() {
    for (;;) {
      auto m = receive();
      if (!m || (!m->has_frame() && !m->has_heartbeat())) return m;
    }
  }
  pb::ServerMessage ask(pb::ClientMessage m, std::uint64_t id) {
    m.set_request_id(id);
    send(m);
    auto r = reply();
    EXPECT_TRUE(r.has_value()) << "no reply to request " << id;
    return r.value_or(pb::ServerMessage{});
  }
  bool closed() const { return closed_; }
  // True once the server ended the connection within the read deadline.
  bool wait_closed() {
    for (int i = 0; i < 1000 && !closed_; ++i) receive_raw();
    return closed_;
  }

 private:
  net::io_context io_;
  websocket::stream<tcp::socket> ws_;
  websocket::response_type response_;
  beast::error_code error_;
  bool closed_ = false;
};

pb::ClientMessage hello() {
  pb::ClientMessage m;
  m.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
  m.mutable_hello()->set_client_name("http test");
  return m;
}

server::ServerConfig http_config() {
  server::ServerConfig cfg;
  cfg.http_port = 0;
  return cfg;
}

// A web root with an index and a script, removed with the object.
struct WebRoot {
  WebRoot() {
    dir = std::filesystem::temp_directory_path() / ("gmr_web_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir / "sub");
    std::ofstream(dir / "index.html") << "<!doctype html><title>gmr</title>";
    std::ofstream(dir / "sub" / "app.js") << "export const x = 1;\n";
  }
  ~WebRoot() { std::filesystem::remove_all(dir); }
  std::filesystem::path dir;
};

TEST(Http, HealthzAnswersWhileLoadingAndReadyzOnceTheLibraryIsThere) {
  server::ServerConfig cfg = http_config();
  cfg.port = 0;
  cfg.udp_port = 0;
  server::Server s(cfg);  // its library comes later
  s.start();
  const std::uint16_t port = s.http_port();
  ASSERT_NE(port, 0);
  EXPECT_EQ(get(port, "/healthz").status, 200u);
  const auto loading = get(port, "/readyz");
  EXPECT_EQ(loading.status, 503u);
  EXPECT_EQ(loading.body, "loading the library\n");
  const auto early = refused_upgrade(port, "gmr.stream.v1");
  EXPECT_EQ(early.status, 503u);
  EXPECT_NE(early.body.find("still loading"), std::string::npos) << early.body;
  // A TCP client that connects meanwhile waits, and is answered once ready.
  RawConnection tcp_client(s.tcp_port());
  tcp_client.send(hello());
  EXPECT_FALSE(tcp_client.receive(std::chrono::milliseconds(300)).has_value());
  s.set_library(test_library());
  auto reply = tcp_client.reply();
  ASSERT_TRUE(reply.has_value());
  EXPECT_TRUE(reply->has_hello());
  const auto ready = get(port, "/readyz");
  EXPECT_EQ(ready.status, 200u);
  EXPECT_EQ(ready.body, "ready: " + std::to_string(test_library().size()) + " motions\n");
  WsClient late(port, "gmr.stream.v1");
  EXPECT_TRUE(late.open());
  s.stop();
}

TEST(Http, ServesItsFilesAndSaysWhatIsWrongWithABadRequest) {
  WebRoot web;
  server::ServerConfig cfg = http_config();
  cfg.web_root = web.dir.string();
  cfg.three_dir = (web.dir / "sub").string();
  TestServer s(cfg);
  const std::uint16_t port = s.server.http_port();

  const auto index = get(port, "/");
  EXPECT_EQ(index.status, 200u);
  EXPECT_EQ(index.body, "<!doctype html><title>gmr</title>");
  EXPECT_EQ(index.content_type, "text/html; charset=utf-8");
  const auto script = get(port, "/sub/app.js?v=1");
  EXPECT_EQ(script.status, 200u);
  EXPECT_EQ(script.content_type, "text/javascript; charset=utf-8");
  EXPECT_EQ(get(port, "/three/app.js").body, "export const x = 1;\n");  // three_dir
  const auto head = http_request(port, http::verb::head, "/sub/app.js");
  EXPECT_EQ(head.status, 200u);
  EXPECT_EQ(head.content_length, "20");
  EXPECT_TRUE(head.body.empty());

  EXPECT_EQ(get(port, "/missing.js").status, 404u);
  EXPECT_EQ(get(port, "/sub").status, 404u);  // a folder is not a file
  EXPECT_EQ(get(port, "/../etc/passwd").status, 400u);
  EXPECT_EQ(get(port, "/three/../../etc/passwd").status, 400u);
  EXPECT_EQ(get(port, "/sub//app.js").status, 400u);
  EXPECT_EQ(get(port, "/%2e%2e/etc/passwd").status, 400u);
  EXPECT_EQ(http_request(port, http::verb::post, "/").status, 405u);
  const auto upgrade_needed = get(port, "/ws");
  EXPECT_EQ(upgrade_needed.status, 426u);
  EXPECT_NE(upgrade_needed.body.find("gmr.stream.v1.json"), std::string::npos);
  // Headers past 8 KiB, and bytes that are not HTTP.
  const std::string huge = "GET / HTTP/1.1\r\nHost: x\r\nX-Pad: " + std::string(10000, 'a') + "\r\n\r\n";
  EXPECT_EQ(http_request(port, http::verb::get, "/", huge).status, 431u);
  const std::string with_body = "POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 5\r\n\r\nhello";
  EXPECT_EQ(http_request(port, http::verb::post, "/", with_body).status, 413u);
  const auto garbage = http_request(port, http::verb::get, "/", "\x16\x03\x01 not http\r\n\r\n");
  EXPECT_EQ(garbage.status, 400u);
  EXPECT_NE(garbage.body.find("bad HTTP request"), std::string::npos);
}

// Silent sockets that hold a session each (connected, never a byte).
std::vector<tcp::socket> silent_sockets(net::io_context& io, std::uint16_t port, int n, const std::string& from) {
  std::vector<tcp::socket> out;
  for (int i = 0; i < n; ++i) {
    out.emplace_back(io);
    out.back().open(tcp::v4());
    out.back().bind(tcp::endpoint(net::ip::make_address(from), 0));
    out.back().connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), port));
  }
  return out;
}

// Before: 64 sockets from one address that sent nothing held every session,
// and /healthz, /readyz and /metrics answered 503 for as long as they were
// re-opened (the shipped Kubernetes probes then restarted the pod). Now one
// address holds at most its share, and when the sessions are full the oldest
// one still waiting for a request makes room: the probes always get in.
TEST(Http, SilentSocketsCannotLockOutTheHealthProbes) {
  server::ServerConfig cfg = http_config();
  cfg.max_http_sessions = 8;
  cfg.max_http_sessions_per_address = 4;
  TestServer s(cfg);
  const std::uint16_t port = s.server.http_port();
  net::io_context io;
  // One address: its fifth is refused, saying why; another address still gets in.
  auto first = silent_sockets(io, port, 4, "127.0.0.2");
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // accepted
  const auto refused = http_request(port, http::verb::get, "/healthz", {}, "127.0.0.2");
  EXPECT_EQ(refused.status, 503u);
  EXPECT_NE(refused.body.find("from one address"), std::string::npos) << refused.body;
  EXPECT_EQ(http_request(port, http::verb::get, "/healthz", {}, "127.0.0.5").status, 200u);
  // Two addresses fill every session; the probes still answer, each time.
  auto second = silent_sockets(io, port, 4, "127.0.0.3");
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  for (const std::string target : {"/healthz", "/readyz", "/metrics", "/healthz"}) {
    EXPECT_EQ(http_request(port, http::verb::get, target, {}, "127.0.0.4").status, 200u) << target;
    // The attacker re-opens what was closed to make room.
    auto more = silent_sockets(io, port, 1, "127.0.0.3");
    for (auto& m : more) second.push_back(std::move(m));
  }
}

// A request head that trickles in is cut off at the head deadline.
TEST(Http, ARequestHeadMustArriveWithinItsDeadline) {
  server::ServerConfig cfg = http_config();
  cfg.http_head_timeout = std::chrono::milliseconds(300);
  TestServer s(cfg);
  net::io_context io;
  tcp::socket slow(io);
  slow.connect(tcp::endpoint(net::ip::make_address("127.0.0.1"), s.server.http_port()));
  const std::string head = "GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ";
  const auto start = std::chrono::steady_clock::now();
  bool closed = false;
  for (int i = 0; i < 100 && !closed; ++i) {  // a byte every 50 ms: 5 s if it were let through
    boost::system::error_code ec;
    net::write(slow, net::buffer(head.substr(0, std::min<std::size_t>(head.size(), static_cast<std::size_t>(i + 1)))),
               ec);
    closed = ec.failed();
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_TRUE(closed) << "the trickle went on for " << seconds << " s";
  std::fprintf(stderr, "a trickled request head was cut off after %.2f s (deadline 0.3 s)\n", seconds);
}

// DNS rebinding: a page of evil.example whose name now resolves to this
// server sends Host: evil.example and Origin: http://evil.example, which
// matched before (101 and the control role on a server without tokens;
// /metrics answered any Host). Addresses, localhost and --allow-host names pass.
TEST(Http, AHostNameThatIsNotTheServersIsRefused) {
  server::ServerConfig cfg = http_config();
  cfg.http_allowed_hosts = {"gmr.internal"};
  TestServer s(cfg);
  const std::uint16_t port = s.server.http_port();
  const std::string p = std::to_string(port);
  const auto rebound = refused_upgrade(port, "gmr.stream.v1", "http://evil.example:" + p, "evil.example");
  EXPECT_EQ(rebound.status, 403u);
  EXPECT_NE(rebound.body.find("Host 'evil.example:" + p + "' is not an address or a name of this server"),
            std::string::npos)
      << rebound.body;
  auto metrics_with = [&](const std::string& host) {
    return http_request(port, http::verb::get, "/metrics", "GET /metrics HTTP/1.1\r\nHost: " + host + "\r\n\r\n");
  };
  EXPECT_EQ(metrics_with("evil.example:" + p).status, 403u);
  EXPECT_EQ(metrics_with("127.0.0.1:" + p).status, 200u);
  EXPECT_EQ(metrics_with("[::1]:" + p).status, 200u);
  EXPECT_EQ(metrics_with("localhost:" + p).status, 200u);
  EXPECT_EQ(metrics_with("GMR.internal:" + p).status, 200u);
  EXPECT_EQ(get(port, "/healthz").status, 200u);
  // A page of an allowed name opens the WebSocket.
  WsClient named(port, "gmr.stream.v1", "http://gmr.internal:" + p, "gmr.internal:" + p);
  EXPECT_TRUE(named.open());
}

TEST(WebSocket, CarriesTheProtocolInBinaryWithFramesEqualToAQuery) {
  TestServer s(http_config());
  WsClient ws(s.server.http_port(), "gmr.stream.v1");
  ASSERT_TRUE(ws.open());
  EXPECT_EQ(ws.chosen_protocol(), "gmr.stream.v1");
  EXPECT_TRUE(ws.ask(hello(), 1).has_hello());
  pb::ClientMessage list;
  list.mutable_list_motions();
  EXPECT_EQ(ws.ask(list, 2).motions().motions_size(), static_cast<int>(test_library().size()));
  pb::ClientMessage create;
  create.mutable_create_view()->set_motion("walk");
  const std::uint32_t view = ws.ask(create, 3).view().view_id();
  pb::ClientMessage shift;
  shift.mutable_shift_root()->set_view_id(view);
  shift.mutable_shift_root()->set_joint("l_wrist");
  ASSERT_TRUE(ws.ask(shift, 4).has_view());
  pb::ClientMessage query;
  query.mutable_query_frames()->set_view_id(view);
  query.mutable_query_frames()->set_begin(0);
  query.mutable_query_frames()->set_end(240);
  const pb::FrameBlock block = ws.ask(query, 5).frames();
  const int joints = block.joints_size();
  ASSERT_GT(joints, 0);
  pb::ClientMessage sub;
  sub.mutable_subscribe()->set_view_id(view);
  sub.mutable_subscribe()->set_precision(pb::PRECISION_FLOAT64);
  sub.mutable_subscribe()->set_rate_hz(240);
  sub.mutable_subscribe()->set_max_frames(40);
  ASSERT_TRUE(ws.ask(sub, 6).has_subscribed());
  int frames = 0;
  while (auto m = ws.receive()) {
    if (m->has_subscription_ended()) break;
    if (!m->has_frame()) continue;
    const auto& f = m->frame();
    ASSERT_EQ(f.positions_f64_size(), joints * 3);
    const std::size_t at = f.frame_index() * static_cast<std::size_t>(joints) * 3;
    for (int k = 0; k < joints * 3; ++k) ASSERT_EQ(f.positions_f64(k), block.positions(static_cast<int>(at) + k));
    ++frames;
  }
  EXPECT_EQ(frames, 40);
}

TEST(WebSocket, SpeaksProtobufsJsonMappingAndRefusesBadJsonWithAReason) {
  TestServer s(http_config());
  WsClient ws(s.server.http_port(), "chat, gmr.stream.v1.json");
  ASSERT_TRUE(ws.open());
  EXPECT_EQ(ws.chosen_protocol(), "gmr.stream.v1.json");
  ws.send_text(R"({"requestId": "1", "hello": {"protocolVersion": 1, "clientName": "json"}})");
  bool text = false;
  auto reply = ws.receive_raw(&text);
  ASSERT_TRUE(reply.has_value());
  EXPECT_TRUE(text);
  pb::ServerMessage m;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(*reply, &m).ok()) << *reply;
  EXPECT_EQ(m.request_id(), 1u);
  EXPECT_TRUE(m.has_hello());

  for (const std::string& bad : {std::string("{not json"), std::string(R"({"requestId": 2, "noSuchRequest": {}})")}) {
    ws.send_text(bad);
    reply = ws.receive_raw();
    ASSERT_TRUE(reply.has_value());
    ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(*reply, &m).ok()) << *reply;
    EXPECT_EQ(m.error().code(), pb::ERROR_CODE_BAD_REQUEST) << bad;
    EXPECT_NE(m.error().message().find("JSON"), std::string::npos) << m.error().message();
  }
  // A refusal comes back in JSON like any reply; binary requests work too.
  ws.send_text(R"({"requestId": "3", "createView": {"motion": "nope"}})");
  reply = ws.receive_raw();
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(*reply, &m).ok());
  EXPECT_EQ(m.error().code(), pb::ERROR_CODE_NOT_FOUND);
  EXPECT_NE(reply->find("\"ERROR_CODE_NOT_FOUND\""), std::string::npos) << *reply;
  pb::ClientMessage list;
  list.set_request_id(4);
  list.mutable_list_motions();
  ws.send(list);
  reply = ws.receive_raw(&text);
  EXPECT_TRUE(text);
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(*reply, &m).ok());
  EXPECT_EQ(m.motions().motions_size(), static_cast<int>(test_library().size()));
}

// A JSON client's large replies (a block of frames) are turned into JSON on
// the server's conversion thread, not its control loop (before: 4 such
// clients took 0.57 core of it); the write slot waits for them, so replies
// still come in the order of the requests.
TEST(WebSocket, LargeJsonRepliesAreMadeOffTheControlLoopInOrder) {
  TestServer s(http_config());
  WsClient ws(s.server.http_port(), "gmr.stream.v1.json");
  ASSERT_TRUE(ws.open());
  pb::ClientMessage m = request(1);
  m.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
  ws.send(m);
  pb::ServerMessage reply;
  auto raw = ws.receive_raw();
  ASSERT_TRUE(raw && google::protobuf::util::JsonStringToMessage(*raw, &reply).ok());
  m = request(2);
  m.mutable_create_view()->set_motion("walk");
  ws.send(m);
  raw = ws.receive_raw();
  ASSERT_TRUE(raw && google::protobuf::util::JsonStringToMessage(*raw, &reply).ok());
  const std::uint32_t view = reply.view().view_id();
  const auto frames = static_cast<std::uint32_t>(reply.view().frame_count());
  const int joints = reply.view().skeleton().joints_size();
  ASSERT_GT(frames, 10u);

  const std::uint64_t aside_before = server::WsConnection::converted_aside();
  // A large block, then a small request at once, then a small block.
  pb::ClientMessage block = request(10);
  block.mutable_query_frames()->set_view_id(view);
  block.mutable_query_frames()->set_begin(0);
  block.mutable_query_frames()->set_end(frames);
  block.mutable_query_frames()->set_orientations(true);
  ASSERT_GT(block.ByteSizeLong(), 0u);
  ws.send(block);
  pb::ClientMessage list = request(11);
  list.mutable_list_motions();
  ws.send(list);
  pb::ClientMessage small = request(12);
  small.mutable_query_frames()->set_view_id(view);
  small.mutable_query_frames()->set_begin(0);
  ws.send(small);
  std::vector<std::uint64_t> order;
  std::size_t big_positions = 0, big_bytes = 0;
  while (order.size() < 3) {
    raw = ws.receive_raw();
    ASSERT_TRUE(raw.has_value()) << "a reply did not come";
    ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(*raw, &reply).ok());
    if (reply.request_id() == 0) continue;  // a heartbeat
    order.push_back(reply.request_id());
    if (reply.request_id() == 10) {
      ASSERT_TRUE(reply.has_frames()) << reply.DebugString().substr(0, 300);
      big_bytes = raw->size();
      big_positions = static_cast<std::size_t>(reply.frames().positions_size());
    }
  }
  EXPECT_EQ(order, (std::vector<std::uint64_t>{10, 11, 12}));
  EXPECT_EQ(big_positions, static_cast<std::size_t>(frames) * static_cast<std::size_t>(joints) * 3);
  EXPECT_GE(server::WsConnection::converted_aside(), aside_before + 1)
      << "a reply of " << big_bytes << " bytes of JSON was made on the control loop";
}

TEST(WebSocket, UnknownSubprotocolsAndForeignPagesAreRefused) {
  server::ServerConfig cfg = http_config();
  cfg.http_allowed_origins = {"http://viewer.example:8080"};
  TestServer s(cfg);
  const std::uint16_t port = s.server.http_port();
  WsClient other(port, "mqtt");
  EXPECT_FALSE(other.open());
  EXPECT_EQ(refused_upgrade(port, "mqtt").status, 400u);
  WsClient foreign(port, "gmr.stream.v1", "http://evil.example");
  EXPECT_FALSE(foreign.open());
  const auto refused = refused_upgrade(port, "gmr.stream.v1", "http://evil.example");
  EXPECT_EQ(refused.status, 403u);
  EXPECT_NE(refused.body.find("another origin"), std::string::npos) << refused.body;
  WsClient own(port, "gmr.stream.v1", "http://127.0.0.1:" + std::to_string(port));
  EXPECT_TRUE(own.open());
  WsClient allowed(port, "gmr.stream.v1", "http://viewer.example:8080");
  EXPECT_TRUE(allowed.open());
  WsClient program(port, "");  // no Origin, no subprotocol: a program, binary
  EXPECT_TRUE(program.open());
  EXPECT_TRUE(program.ask(hello(), 1).has_hello());
}

TEST(WebSocket, HasTheLimitsOfATcpClient) {
  server::ServerConfig cfg = http_config();
  cfg.max_message_bytes = 8192;
  cfg.max_connections = 3;
  cfg.handshake_timeout = std::chrono::milliseconds(300);
  TestServer s(cfg);
  const std::uint16_t port = s.server.http_port();

  // Bytes that are not a ClientMessage: an error reply, the connection stays.
  WsClient ws(port, "gmr.stream.v1");
  ASSERT_TRUE(ws.open());
  ws.send_bytes("\xff\xff\xff not protobuf");
  auto bad = ws.reply();
  ASSERT_TRUE(bad.has_value());
  EXPECT_EQ(bad->error().code(), pb::ERROR_CODE_BAD_REQUEST);
  EXPECT_TRUE(ws.ask(hello(), 1).has_hello());

  // No Hello in time: closed, as over TCP.
  WsClient silent(port, "gmr.stream.v1");
  ASSERT_TRUE(silent.open());
  EXPECT_TRUE(silent.wait_closed());

  // WebSockets and TCP clients share max_connections.
  RawConnection tcp_client(s.port());
  tcp_client.handshake();
  WsClient third(port, "gmr.stream.v1");
  ASSERT_TRUE(third.open());
  const auto fourth = refused_upgrade(port, "gmr.stream.v1");
  EXPECT_EQ(fourth.status, 503u);
  EXPECT_NE(fourth.body.find("--max-connections"), std::string::npos) << fourth.body;

  // A message longer than max_message_bytes closes the connection.
  ws.send_bytes(std::string(9000, 'x'));
  EXPECT_TRUE(ws.wait_closed());
}

// The watchdog wakes at a link's next deadline. A WebSocket (like TLS)
// writes its heartbeat asynchronously, so the watchdog re-arms while that
// write is in flight: the next heartbeat must still wake it, not the write
// timeout 20 s later.
TEST(WebSocket, HeartbeatsKeepTheirIntervalThoughWrittenAsynchronously) {
  server::ServerConfig cfg = http_config();
  cfg.heartbeat_interval = std::chrono::milliseconds(100);
  TestServer s(cfg);
  WsClient ws(s.server.http_port(), "gmr.stream.v1");
  ASSERT_TRUE(ws.open());
  EXPECT_TRUE(ws.ask(hello(), 1).has_hello());
  pb::ClientMessage create;
  create.mutable_create_view()->set_motion("walk");
  ASSERT_TRUE(ws.ask(create, 2).has_view());  // holds a view: not idle for holding nothing
  int heartbeats = 0;
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(1500);
  while (std::chrono::steady_clock::now() < until) {
    auto m = ws.receive();
    ASSERT_TRUE(m.has_value()) << "closed after " << heartbeats << " heartbeats";
    heartbeats += m->has_heartbeat() ? 1 : 0;
  }
  // About 14 at 100 ms; a busy machine delays some, never a 20 s gap.
  EXPECT_GE(heartbeats, 5);
}

TEST(WebSocket, AClientThatStopsReadingGetsLatestFramesThenIsClosed) {
  server::ServerConfig cfg = http_config();
  cfg.write_timeout = std::chrono::milliseconds(1500);
  cfg.idle_timeout = std::chrono::seconds(60);
  cfg.socket_send_buffer = 4096;
  TestServer s(cfg);
  WsClient ws(s.server.http_port(), "gmr.stream.v1");
  ASSERT_TRUE(ws.open());
  ASSERT_TRUE(ws.ask(hello(), 1).has_hello());
  pb::ClientMessage create;
  create.mutable_create_view()->set_motion("walk");
  const std::uint32_t view = ws.ask(create, 2).view().view_id();
  pb::ClientMessage sub;
  sub.mutable_subscribe()->set_view_id(view);
  sub.mutable_subscribe()->set_loop(true);
  sub.mutable_subscribe()->set_rate_hz(2000);
  sub.mutable_subscribe()->set_precision(pb::PRECISION_FLOAT64);
  ASSERT_TRUE(ws.ask(sub, 3).has_subscribed());
  // This client reads nothing more. The server drops frames it cannot
  // write (bounded memory), then closes the stuck connection.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  std::uint64_t dropped = 0, max_queued = 0;
  std::size_t connections = 1;
  while (std::chrono::steady_clock::now() < deadline && connections != 0) {
    const auto st = s.server.stats();
    connections = st.connections;
    for (const auto& session : st.sessions) {
      dropped = std::max(dropped, session.frames_dropped);
      max_queued = std::max(max_queued, session.max_queued_bytes);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(connections, 0u) << "the stuck WebSocket was not closed";
  EXPECT_GT(dropped, 0u);
  EXPECT_LE(max_queued, cfg.max_frame_bytes_per_connection + (64u << 10));
}

// frame_to_json writes the JSON mapping by hand, for speed: with every field
// of Frame set (found by reflection, so a field added to the .proto and
// forgotten there fails here), protobuf's own parser reads back the message.
TEST(WebSocket, TheFastFrameJsonIsProtobufsMappingOfEveryField) {
  using google::protobuf::FieldDescriptor;
  pb::ServerMessage m;
  m.set_request_id(std::numeric_limits<std::uint64_t>::max());
  pb::Frame* f = m.mutable_frame();
  const auto* d = pb::Frame::descriptor();
  const auto* r = pb::Frame::GetReflection();
  const std::vector<double> values = {0.1, -2.5e-7, 1e300, 3.0, -0.0, 123456.789012345678, 5e-324};
  for (int i = 0; i < d->field_count(); ++i) {
    const FieldDescriptor* field = d->field(i);
    SCOPED_TRACE(field->name());
    if (field->is_repeated()) {
      for (const double v : values) {
        if (field->cpp_type() == FieldDescriptor::CPPTYPE_DOUBLE) {
          r->AddDouble(f, field, v);
        } else if (field->cpp_type() == FieldDescriptor::CPPTYPE_FLOAT) {
          r->AddFloat(f, field, static_cast<float>(v == 1e300 ? 3.4e38 : v == 5e-324 ? 1.4e-45 : v));
        } else {
          ADD_FAILURE() << "a repeated Frame field of a type frame_to_json does not write";
        }
      }
      continue;
    }
    switch (field->cpp_type()) {
      case FieldDescriptor::CPPTYPE_UINT32:
        r->SetUInt32(f, field, 4000000000u + static_cast<unsigned>(i));
        break;
      case FieldDescriptor::CPPTYPE_UINT64:
        r->SetUInt64(f, field, std::numeric_limits<std::uint64_t>::max() - static_cast<unsigned>(i));
        break;
      case FieldDescriptor::CPPTYPE_INT64:
        r->SetInt64(f, field, std::numeric_limits<std::int64_t>::min() + i);
        break;
      case FieldDescriptor::CPPTYPE_DOUBLE:
        r->SetDouble(f, field, -1234.5678e-9);
        break;
      default:
        ADD_FAILURE() << "a Frame field of a type frame_to_json does not write";
    }
  }
  const std::string json = server::frame_to_json(m);
  pb::ServerMessage back;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(json, &back).ok()) << json;
  std::string differences;
  google::protobuf::util::MessageDifferencer diff;
  diff.ReportDifferencesToString(&differences);
  EXPECT_TRUE(diff.Compare(m, back)) << differences << "\n" << json;

  // Defaults are left out, as protobuf's printer does; non-finite values are strings.
  pb::ServerMessage sparse;
  sparse.mutable_frame()->add_positions_f64(std::numeric_limits<double>::infinity());
  sparse.mutable_frame()->add_positions_f64(-std::numeric_limits<double>::infinity());
  sparse.mutable_frame()->add_positions_f64(std::numeric_limits<double>::quiet_NaN());
  sparse.mutable_frame()->set_server_send_time_ns(-5);
  EXPECT_EQ(server::frame_to_json(sparse),
            R"({"frame":{"serverSendTimeNs":"-5","positionsF64":["Infinity","-Infinity","NaN"]}})");
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(server::frame_to_json(sparse), &back).ok());
  EXPECT_TRUE(std::isnan(back.frame().positions_f64(2)));
  EXPECT_EQ(server::frame_to_json(pb::ServerMessage()), R"({"frame":{}})");
}

}  // namespace
}  // namespace gmr::test
