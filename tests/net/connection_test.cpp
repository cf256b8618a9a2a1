// Connection without views: the transport alone, on a loopback socket, with
// a handler that echoes every message back.
#include "connection.h"

#include <gtest/gtest.h>

#include <future>
#include <optional>
#include <thread>

#include "gmr/wire/framing.h"
#include "net_test_util.h"

namespace gmr::test {
namespace {

namespace net = boost::asio;
using tcp = net::ip::tcp;

class Echo final : public server::Connection::Handler {
 public:
  std::weak_ptr<server::Connection> connection;
  int messages = 0;
  int stops = 0;
  void on_message(const std::string& body) override {
    ++messages;
    if (auto c = connection.lock()) c->send(wire::frame_bytes(body));
  }
  void on_stop() override { ++stops; }
};

// A Connection serving one accepted loopback socket on its own thread.
struct EchoServer {
  explicit EchoServer(server::ConnectionLimits limits) {
    acceptor.open(tcp::v4());
    acceptor.bind(tcp::endpoint(net::ip::make_address("127.0.0.1"), 0));
    acceptor.listen();
    port = acceptor.local_endpoint().port();
    acceptor.async_accept([this, limits](const boost::system::error_code& ec, tcp::socket s) {
      ASSERT_FALSE(ec) << ec.message();
      connection = std::make_shared<server::Connection>(io, std::move(s), 1, limits);
      echo->connection = connection;
      connection->start(echo, [this](std::uint64_t) { ++closed; });
    });
    thread = std::thread([this] { io.run(); });
  }
  ~EchoServer() {
    net::post(io, [this] {
      if (connection) connection->stop("test over");
      work.reset();
    });
    thread.join();
  }
  net::io_context io;
  // Keeps io.run() going after the connection closed, so the test can still post to it.
  std::optional<net::executor_work_guard<net::io_context::executor_type>> work{io.get_executor()};
  tcp::acceptor acceptor{io};
  std::uint16_t port = 0;
  std::shared_ptr<Echo> echo = std::make_shared<Echo>();
  std::shared_ptr<server::Connection> connection;
  int closed = 0;
  std::thread thread;
};

server::ConnectionLimits limits() {
  server::ConnectionLimits l;
  l.max_message_bytes = 1024;
  l.max_reply_queue_bytes = 1 << 20;
  l.frames_per_key = 2;
  l.idle_timeout = std::chrono::seconds(30);
  l.heartbeat_interval = std::chrono::seconds(10);
  l.write_timeout = std::chrono::seconds(10);
  return l;
}

TEST(Connection, DeliversEachMessageAndWritesRepliesInOrder) {
  EchoServer s(limits());
  RawConnection c(s.port);
  for (std::uint64_t id = 1; id <= 20; ++id) c.send(request(id));
  for (std::uint64_t id = 1; id <= 20; ++id) {
    auto back = c.receive();  // the echoed ClientMessage bytes parse as a ServerMessage with the same id
    ASSERT_TRUE(back.has_value());
    EXPECT_EQ(back->request_id(), id);
  }
  c.shutdown_send();
  EXPECT_TRUE(c.wait_closed());
}

TEST(Connection, AnOversizedLengthPrefixClosesItAndStopsTheHandlerOnce) {
  EchoServer s(limits());
  RawConnection c(s.port);
  c.send_bytes(std::string("\x00\x01\x00\x00", 4));  // 65536 > 1024: refused before any body byte
  EXPECT_TRUE(c.wait_closed());
  net::post(s.io, [&] { s.connection->stop("again"); });  // idempotent
  std::promise<std::pair<int, int>> counts;
  net::post(s.io, [&] { counts.set_value({s.echo->stops, s.closed}); });
  const auto [stops, closed] = counts.get_future().get();
  EXPECT_EQ(stops, 1);
  EXPECT_EQ(closed, 1);
  EXPECT_EQ(s.echo->messages, 0);
}

}  // namespace
}  // namespace gmr::test
