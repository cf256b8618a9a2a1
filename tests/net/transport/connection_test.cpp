// Connection without views: the transport alone, on a loopback socket, with
// a handler that echoes every message back; on one thread, or with the
// socket on a lane thread and the handler on a control thread of its own, as
// gmr-server runs it (io_threads.h).
#include "transport/connection.h"

#include <gtest/gtest.h>

#include <atomic>
#include <future>
#include <optional>
#include <set>
#include <thread>

#include "gmr/wire/framing.h"
#include "net_test_util.h"
#include "transport/link.h"

namespace gmr::test {
namespace {

namespace net = boost::asio;
using tcp = net::ip::tcp;

class Echo final : public server::Connection::Handler {
 public:
  std::weak_ptr<server::Connection> connection;
  int messages = 0;
  int stops = 0;
  // Where and how the handler was called: the threads it ran on, and
  // whether two calls ever overlapped.
  std::set<std::thread::id> threads;
  std::atomic<int> inside{0};
  bool overlapped = false;
  // With `hold`, a message is answered only at release(), its connection's
  // reads held meanwhile (what an edit off the I/O thread does).
  bool hold = false;
  std::string held;
  void release() {
    if (auto c = connection.lock()) {
      c->send(wire::frame_bytes(held));
      c->hold_reading(false);
    }
  }
  void on_message(const std::string& body) override {
    if (hold) {
      held = body;
      if (auto c = connection.lock()) c->hold_reading(true);
      return;
    }
    if (inside.fetch_add(1) != 0) overlapped = true;
    threads.insert(std::this_thread::get_id());
    ++messages;
    // Long enough that a connection reading on meanwhile would hand over the next one.
    std::this_thread::sleep_for(std::chrono::microseconds(200));
    if (auto c = connection.lock()) c->send(wire::frame_bytes(body));
    inside.fetch_sub(1);
  }
  void on_stop() override {
    threads.insert(std::this_thread::get_id());
    ++stops;
  }
};

// A Connection serving one accepted loopback socket: on one thread, or
// (`lane`) its socket on a thread of its own and its handler on the control
// thread.
struct EchoServer {
  explicit EchoServer(server::ConnectionLimits limits, bool lane = false) {
    acceptor.open(tcp::v4());
    acceptor.bind(tcp::endpoint(net::ip::make_address("127.0.0.1"), 0));
    acceptor.listen();
    port = acceptor.local_endpoint().port();
    net::io_context& socket_io = lane ? lane_io : io;
    acceptor.async_accept(socket_io, [this, limits, &socket_io](const boost::system::error_code& ec, tcp::socket s) {
      ASSERT_FALSE(ec) << ec.message();
      connection = std::make_shared<server::Connection>(socket_io, std::move(s), 1, limits, nullptr, nullptr,
                                                        server::ConnectionPlacement{&io, 1, nullptr});
      echo->connection = connection;
      // Started from the control thread, as the server starts its connections.
      net::post(io, [this] { connection->start(echo, [this](std::uint64_t) { ++closed; }); });
    });
    thread = std::thread([this] {
      control_thread = std::this_thread::get_id();
      io.run();
    });
    if (lane) lane_thread = std::thread([this] { lane_io.run(); });
  }
  ~EchoServer() {
    net::post(io, [this] {
      if (connection) connection->stop("test over");
      work.reset();
    });
    thread.join();
    net::post(lane_io, [this] { lane_work.reset(); });
    if (lane_thread.joinable()) lane_thread.join();
  }
  net::io_context io;
  net::io_context lane_io;
  // Keep run() going after the connection closed, so the test can still post.
  std::optional<net::executor_work_guard<net::io_context::executor_type>> work{io.get_executor()};
  std::optional<net::executor_work_guard<net::io_context::executor_type>> lane_work{lane_io.get_executor()};
  tcp::acceptor acceptor{io};
  std::uint16_t port = 0;
  std::shared_ptr<Echo> echo = std::make_shared<Echo>();
  std::shared_ptr<server::Connection> connection;
  int closed = 0;
  std::thread::id control_thread;
  std::thread thread, lane_thread;
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

// A client whose reads the server holds (an edit running for it off the
// I/O thread: the handler holds the connection's reads while it has the
// request, as RequestHandler::edit_view does) is waiting for the server, not
// idle, however long that takes; once answered, silence is idleness again.
// The watchdog's ticks of connections with the same limits fall on the same
// instants (multiples of a quarter period), a period or at most a quarter
// more after each asked: 10,000 idle connections wake their I/O thread a few
// times a second, not 8,000 times.
// A connection's frame waits, in power-of-two buckets of microseconds: a
// quantile is its bucket's upper bound; past the last bound, its lower one.
TEST(WaitHistogram, AQuantileIsTheUpperBoundOfItsBucket) {
  using std::chrono::microseconds;
  server::WaitHistogram h;
  EXPECT_EQ(h.quantile_seconds(0.99), 0.0);
  for (int i = 0; i < 99; ++i) h.add(microseconds(10));  // [8, 16) us
  h.add(microseconds(5000));                             // [4096, 8192) us
  EXPECT_EQ(h.count(), 100u);
  EXPECT_DOUBLE_EQ(h.quantile_seconds(0.5), 16e-6);
  EXPECT_DOUBLE_EQ(h.quantile_seconds(0.99), 16e-6);
  EXPECT_DOUBLE_EQ(h.quantile_seconds(1.0), 8192e-6);
  for (int i = 0; i < 5; ++i) h.add(std::chrono::seconds(10));
  EXPECT_DOUBLE_EQ(h.quantile_seconds(0.99), 262144e-6);  // the last bucket, from 2^18 us
  server::WaitHistogram zero;
  zero.add(microseconds(0));
  EXPECT_DOUBLE_EQ(zero.quantile_seconds(0.5), 1e-6);
  // Either side of every bound: 2^j - 1 us is under 2^j, 2^j us is not.
  int sides = 0;
  for (int j = 1; j < 24; ++j) {
    for (std::int64_t us : {(std::int64_t{1} << j) - 1, std::int64_t{1} << j}) {
      server::WaitHistogram one;
      one.add(microseconds(us));
      const int bucket = us < (std::int64_t{1} << j) ? j : j + 1;
      const int bound = bucket < 19 ? bucket : 18;  // the last bucket reports its lower bound
      EXPECT_DOUBLE_EQ(one.quantile_seconds(0.5), static_cast<double>(std::int64_t{1} << bound) * 1e-6) << us;
      ++sides;
    }
  }
  EXPECT_EQ(sides, 46);
}

// A bucket counts past 2^32 (a 1 kHz source's frames in 50 days): a count
// folded in whole, not cut to 32 bits.
TEST(WaitHistogram, ABucketCountsPastTwoToTheThirtySecond) {
  server::WaitHistogram h;
  const std::uint64_t many = (std::uint64_t{1} << 32) + 5;
  h.add_to_bucket(4, many);  // [8, 16) us
  h.add(std::chrono::microseconds(5000));
  EXPECT_EQ(h.count(), many + 1);
  EXPECT_DOUBLE_EQ(h.quantile_seconds(0.99), 16e-6);
}

TEST(ConnectionWatchdog, TicksOfManyConnectionsFallDueTogether) {
  server::ConnectionLimits limits;
  limits.heartbeat_interval = std::chrono::milliseconds(5000);
  limits.idle_timeout = std::chrono::milliseconds(30000);
  limits.write_timeout = std::chrono::milliseconds(20000);
  const auto period = server::watchdog_period(limits, true);
  const server::Clock::duration grain = server::Clock::duration(period) / 4;
  std::set<server::Clock::time_point> instants;
  const auto start = server::Clock::now();
  for (int i = 0; i < 10000; ++i) {
    const auto now = start + std::chrono::microseconds(i * 137);  // connections armed over 1.37 s
    const auto due = server::watchdog_due(limits, true, now);
    ASSERT_GE(due, now + period);
    ASSERT_LT(due, now + period + grain);
    EXPECT_EQ(due.time_since_epoch() % grain, server::Clock::duration::zero());
    instants.insert(due);
  }
  EXPECT_LE(instants.size(), 6u) << "1.37 s of arming falls on a few quarter-period instants";
}

// Before, every link's watchdog ticked each period (a quarter of its
// shortest timeout: 1.25 s by default), so 10,000 multicast subscribers
// were 8,000 timer expiries a second with nothing to do at most of them.
// Now it wakes at the link's first deadline: an idle link once per heartbeat.
TEST(ConnectionWatchdog, ALinkWakesAtItsFirstDeadlineNotEveryPeriod) {
  using std::chrono::milliseconds;
  using std::chrono::seconds;
  server::ConnectionLimits l;
  l.heartbeat_interval = seconds(5);
  l.idle_timeout = seconds(30);
  l.write_timeout = seconds(20);
  l.handshake_timeout = seconds(5);
  const auto period = server::watchdog_period(l, true);
  ASSERT_EQ(period, milliseconds(1250));
  const server::Clock::duration grain = server::Clock::duration(period) / 4;
  const auto now = server::Clock::now();
  server::LinkTimes t;
  t.established = true;
  t.holding = true;
  t.started = now - seconds(60);
  t.last_read = t.last_frames_written = t.last_held = now - seconds(1);
  const auto next = [&](server::Clock::time_point last_write, bool ready, bool polled) {
    const auto due = server::watchdog_next(t, last_write, ready, polled, l, now);
    EXPECT_EQ(due.time_since_epoch() % grain, server::Clock::duration::zero());
    return due;
  };
  // between `at` and a grain past it
  const auto near = [&](server::Clock::time_point due, server::Clock::time_point at) {
    return due > at && due <= at + grain;
  };
  // Idle, written a second ago: the heartbeat is due in 4 s, and the tick with it.
  EXPECT_TRUE(near(next(now - seconds(1), true, false), now + seconds(4)));
  // Until the link is ready (TLS) no heartbeat: the write and idle timeouts bound the tick.
  EXPECT_TRUE(near(next(now - seconds(1), false, false), now + seconds(20)));
  // A write in flight for 1 s: a heartbeat due in 4 s still wakes the tick
  // (the write, a TLS or WebSocket heartbeat's, is likely done by then)...
  t.writing = true;
  t.write_started = now - seconds(1);
  EXPECT_TRUE(near(next(now - seconds(1), true, false), now + seconds(4)));
  // ...but one overdue does not (none goes out while writing): the write's timeout in 19 s.
  EXPECT_TRUE(near(next(now - seconds(10), true, false), now + seconds(19)));
  t.writing = false;
  // Holding nothing since 28 s ago: its idle timeout in 2 s.
  t.holding = false;
  t.last_held = now - seconds(28);
  EXPECT_TRUE(near(next(now, true, false), now + seconds(2)));
  t.holding = true;
  // Before Hello: the handshake deadline.
  t.established = false;
  t.started = now - seconds(1);
  EXPECT_TRUE(near(next(now, true, false), now + seconds(4)));
  t.established = true;
  // Reads waiting for the budget or the Handler: every period, as before.
  EXPECT_TRUE(near(next(now - seconds(1), true, true), now + period));
  // A deadline already passed: the next grain (the verdict runs there).
  EXPECT_TRUE(near(next(now - seconds(10), true, false), now));
  // However long the heartbeat, never further than the shorter of the write
  // and idle timeouts (a write starting later must not go unwatched).
  l.heartbeat_interval = seconds(600);
  l.write_timeout = seconds(10);
  const auto long_period = server::watchdog_period(l, true);
  const auto due = server::watchdog_next(t, now, true, false, l, now);
  EXPECT_GT(due, now + seconds(10));
  EXPECT_LE(due, now + seconds(10) + long_period / 4);
}

TEST(Connection, HeldReadsAreNotIdleness) {
  server::ConnectionLimits l = limits();
  l.idle_timeout = std::chrono::milliseconds(200);
  l.heartbeat_interval = std::chrono::seconds(60);
  EchoServer s(l);
  s.echo->hold = true;
  RawConnection c(s.port);
  c.send(request(1));
  EXPECT_FALSE(c.readable(std::chrono::milliseconds(1000))) << "closed or answered while held";
  net::post(s.io, [&] { s.echo->release(); });
  auto back = c.receive();
  ASSERT_TRUE(back.has_value()) << "the held request was not answered";
  EXPECT_EQ(back->request_id(), 1u);
  EXPECT_TRUE(c.wait_closed(std::chrono::seconds(5))) << "a silent client was never timed out";
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

// gmr-server's shape: the socket on a lane thread, the handler on the
// control thread. Pipelined requests reach the handler one at a time, in
// order, on the control thread only, and the replies it queues from there go
// out in order; a stop asked for on the control thread closes the socket on
// the lane and tells the handler once.
TEST(Connection, OnALaneHandsEachRequestToTheControlThreadOneAtATimeInOrder) {
  EchoServer s(limits(), /*lane=*/true);
  RawConnection c(s.port);
  std::string burst;
  for (std::uint64_t id = 1; id <= 50; ++id) burst += wire::frame_message(request(id)).value();
  c.send_bytes(burst);  // all 50 at once: the lane could read them all before the first is answered
  for (std::uint64_t id = 1; id <= 50; ++id) {
    auto back = c.receive();
    ASSERT_TRUE(back.has_value()) << "reply " << id;
    EXPECT_EQ(back->request_id(), id);
  }
  std::promise<void> stopped;
  net::post(s.io, [&] {
    s.connection->stop("asked on the control thread");
    s.connection->stop("again");  // idempotent
    stopped.set_value();
  });
  stopped.get_future().get();
  EXPECT_TRUE(c.wait_closed());
  std::promise<std::tuple<int, int, int, std::set<std::thread::id>, bool>> seen;
  net::post(s.io, [&] {
    seen.set_value({s.echo->messages, s.echo->stops, s.closed, s.echo->threads, s.echo->overlapped});
  });
  const auto [messages, stops, closed, threads, overlapped] = seen.get_future().get();
  EXPECT_EQ(messages, 50);
  EXPECT_EQ(stops, 1);
  EXPECT_EQ(closed, 1);
  EXPECT_FALSE(overlapped) << "two requests were with the handler at once";
  EXPECT_EQ(threads, std::set<std::thread::id>{s.control_thread}) << "the handler ran off the control thread";
}

// The connection reads what arrived (up to 512 bytes) and takes each whole
// request out of it; a body longer than what came with its prefix is read
// on into a buffer of its own. Whatever the cut of the bytes (one at a time,
// at the prefix, around the 512-byte read, all at once), every request
// reaches the handler whole and once, in order, on one thread or on a lane.
TEST(Connection, RequestsArriveWholeAndInOrderHoweverTheBytesAreCut) {
  // Bodies (echoed back, so each parses as a ServerMessage with its id)
  // around every edge of the read: empty, tiny, ending just before, at and
  // past the first read, and two reads long.
  std::vector<std::string> bodies;
  std::string stream;
  std::uint64_t id = 0;
  for (std::size_t text : {0, 1, 40, 490, 495, 496, 497, 498, 499, 500, 501, 700, 1000}) {
    pb::ServerMessage m;
    m.set_request_id(++id);
    if (text > 0) m.mutable_error()->set_message(std::string(text, 'a' + static_cast<char>(id % 26)));
    bodies.push_back(m.SerializeAsString());
    ASSERT_LE(bodies.back().size(), limits().max_message_bytes);
    stream += wire::frame_bytes(bodies.back());
  }
  stream += wire::frame_bytes("");  // an empty body: an empty message
  bodies.emplace_back();
  int runs = 0;
  for (const bool lane : {false, true}) {
    for (const std::size_t cut : {std::size_t{1}, std::size_t{3}, std::size_t{4}, std::size_t{5}, std::size_t{511},
                                  std::size_t{512}, std::size_t{513}, stream.size()}) {
      EchoServer s(limits(), lane);
      RawConnection c(s.port);
      for (std::size_t at = 0; at < stream.size(); at += cut) {
        c.send_bytes(stream.substr(at, cut));
        if (cut < stream.size()) std::this_thread::sleep_for(std::chrono::microseconds(cut < 8 ? 50 : 1000));
      }
      for (std::size_t k = 0; k < bodies.size(); ++k) {
        auto back = c.receive();
        ASSERT_TRUE(back.has_value()) << "reply " << k << ", cut " << cut << (lane ? ", on a lane" : "");
        EXPECT_EQ(back->SerializeAsString(), bodies[k]) << "reply " << k << ", cut " << cut;
      }
      c.shutdown_send();
      EXPECT_TRUE(c.wait_closed());
      std::promise<int> messages;
      net::post(s.io, [&] { messages.set_value(s.echo->messages); });
      EXPECT_EQ(messages.get_future().get(), static_cast<int>(bodies.size())) << "cut " << cut;
      ++runs;
    }
  }
  EXPECT_EQ(runs, 16);
}

// A client that closes while its request is with the handler: the lane sees
// the socket close, the handler finishes, is told once, and nothing more is
// read or handed over.
TEST(Connection, OnALaneAClientClosingMidRequestStopsItOnce) {
  EchoServer s(limits(), /*lane=*/true);
  {
    RawConnection c(s.port);
    for (std::uint64_t id = 1; id <= 5; ++id) c.send(request(id));
  }  // closed at once, replies unread
  std::promise<std::pair<int, int>> counts;
  for (int i = 0; i < 200; ++i) {
    std::promise<int> closed;
    net::post(s.io, [&] { closed.set_value(s.closed); });
    if (closed.get_future().get() == 1) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  net::post(s.io, [&] { counts.set_value({s.echo->stops, s.closed}); });
  const auto [stops, closed] = counts.get_future().get();
  EXPECT_EQ(stops, 1);
  EXPECT_EQ(closed, 1);
  EXPECT_LE(s.echo->messages, 5);
}

}  // namespace
}  // namespace gmr::test
