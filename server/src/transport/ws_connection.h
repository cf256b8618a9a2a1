// WsConnection: the transport of one WebSocket client (the browser viewer, or
// any program that prefers WebSocket to raw TCP). One WebSocket message is
// one protocol message, without the TCP length prefix; the requests, replies,
// limits, error replies and slow-client policy are those of Connection:
//
//   upgrade (subprotocol picks the format) --> Handler::on_message(body)
//   send(reply) -------+
//   push_frame(key) ---+--> outbox --one message written at a time--> socket
//                          replies in order, then frames; per key at most
//                          frames_per_key waiting (the oldest gives way);
//                          a frame past its staleness bound is dropped
//   watchdog: Hello deadline, idle timeout, stuck write, heartbeat
//
// Two formats (docs/protocol.md, "WebSocket"): "gmr.stream.v1" carries the
// protobuf binary messages in binary WebSocket messages; "gmr.stream.v1.json"
// carries protobuf's canonical JSON mapping of the same messages in text
// messages, for pages that have no protobuf runtime. A client that names no
// subprotocol gets binary.
#pragma once

#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/websocket.hpp>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "transport/connection.h"
#include "transport/frame_queue.h"
#include "transport/outbox.h"

namespace gmr::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;

// protobuf's JSON mapping of a ServerMessage carrying a Frame, written
// directly: MessageToJsonString takes 69 us for a 38-joint float64 frame,
// parsing it and this 4.6 us (bench/wire_bench.cpp). Parsed back with
// JsonStringToMessage it gives `m` again, every Frame field included
// (tests/net/server_http_test.cpp checks each one).
std::string frame_to_json(const pb::ServerMessage& m);

inline constexpr const char* kWsBinaryProtocol = "gmr.stream.v1";
inline constexpr const char* kWsJsonProtocol = "gmr.stream.v1.json";

class WsConnection final : public CountingOutbox, public std::enable_shared_from_this<WsConnection> {
 public:
  enum class Format { kBinary, kJson };

  // `socket` carried `upgrade`, an HTTP request websocket::is_upgrade accepted.
  // `budget` (may be null) outlives the connection.
  WsConnection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits,
               BufferBudget* budget);
  ~WsConnection() override;

  // The format the client's Sec-WebSocket-Protocol asks for; nullopt: none
  // this server speaks (the upgrade is then refused).
  static std::optional<Format> format_of(const http::request<http::string_body>& upgrade);

  // Completes the upgrade, then reads messages into `handler`. `on_closed`
  // runs once when the connection stopped.
  void start(http::request<http::string_body> upgrade, Format format, std::shared_ptr<Connection::Handler> handler,
             std::function<void(std::uint64_t)> on_closed);

  void set_frame_wait_histogram(prometheus::Histogram* h) { frame_wait_ = h; }

  // Outbox (outbox.h).
  std::uint64_t id() const override { return id_; }
  const char* transport() const override { return "websocket"; }
  bool stopped() const override { return stopped_; }
  bool closing() const override { return stopped_ || close_after_flush_; }
  void send(std::string framed) override;
  bool push_frame(std::uint32_t key, std::string head, std::shared_ptr<const std::string> body,
                  Clock::duration max_age = {}) override;
  bool congested(std::uint32_t key) const override;
  void discard_frames(std::uint32_t key) override;
  void send_frames_now(std::uint32_t key) override;
  std::uint64_t end_frames(std::uint32_t key) override;
  void close_after_reply() override;
  void established() override { established_ = true; }
  void hold_reading(bool hold) override;
  void stop(const std::string& reason) override;
  void finish() override;
  ConnectionCounters counters() const override;

 private:
  void read();
  void on_read(const boost::system::error_code& ec, std::size_t bytes);
  void flush();
  void write(std::string message, bool frame);
  void arm_watchdog();
  void close_socket();
  std::uint64_t queued_bytes() const { return reply_bytes_ + frames_.bytes() + in_flight_bytes_; }
  void account();
  bool may_read() const;
  // A framed protocol message (prefix, then body) as this client's format
  // wants it; empty when it cannot be converted (logged).
  std::string to_client(std::string_view framed) const;

  websocket::stream<beast::tcp_stream> ws_;
  std::uint64_t id_;
  ConnectionLimits limits_;
  BufferBudget* budget_;
  std::uint64_t accounted_ = 0;
  std::string peer_;
  Format format_ = Format::kBinary;
  bool open_ = false;  // the upgrade completed
  bool established_ = false;
  bool stopped_ = false;
  bool close_after_flush_ = false;
  bool read_paused_ = false;
  bool reads_held_ = false;  // hold_reading
  bool reading_ = false;
  bool writing_ = false;
  bool socket_closed_ = false;
  std::shared_ptr<Connection::Handler> handler_;
  std::function<void(std::uint64_t)> on_closed_;
  beast::flat_buffer in_;
  std::string out_;  // the message being written
  std::deque<std::string> replies_;  // framed, as RequestHandler gives them
  std::uint64_t reply_bytes_ = 0;
  FrameQueue frames_;
  std::uint64_t in_flight_bytes_ = 0;
  std::uint32_t next_key_ = 0;  // frames are written key by key from here (round robin)
  Clock::time_point started_ = Clock::now();
  Clock::time_point write_started_{}, last_read_{}, last_write_{}, last_frames_written_{};
  Clock::time_point frame_in_flight_pushed_ = Clock::time_point::max();
  net::steady_timer watchdog_;
  prometheus::Histogram* frame_wait_ = nullptr;
};

}  // namespace gmr::server
