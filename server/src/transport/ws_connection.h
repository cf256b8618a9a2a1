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
#include "transport/queued_outbox.h"
#include "transport/ws_json.h"

namespace gmr::server {

namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;

inline constexpr const char* kWsBinaryProtocol = "gmr.stream.v1";
inline constexpr const char* kWsJsonProtocol = "gmr.stream.v1.json";

class WsConnection final : public QueuedOutbox, public std::enable_shared_from_this<WsConnection> {
 public:
  enum class Format { kBinary, kJson };

  // `socket` carried `upgrade`, an HTTP request websocket::is_upgrade accepted.
  // `budget` (may be null) outlives the connection. `convert`: where JSON
  // replies of kConvertAsideFrom bytes or more are made (none: here).
  WsConnection(net::io_context& io, tcp::socket socket, std::uint64_t id, const ConnectionLimits& limits,
               BufferBudget* budget, std::optional<net::any_io_executor> convert = std::nullopt);
  // A reply this large (a block of QueryFrames) is turned into JSON off the
  // control loop: the write slot waits for it, so replies keep their order.
  static constexpr std::size_t kConvertAsideFrom = 64 << 10;
  // Replies converted so, by every connection since the process started.
  static std::uint64_t converted_aside();

  // The format the client's Sec-WebSocket-Protocol asks for; nullopt: none
  // this server speaks (the upgrade is then refused).
  static std::optional<Format> format_of(const http::request<http::string_body>& upgrade);

  // Completes the upgrade, then reads messages into `handler`. `on_closed`
  // runs once when the connection stopped.
  void start(http::request<http::string_body> upgrade, Format format, std::shared_ptr<Connection::Handler> handler,
             std::function<void(std::uint64_t)> on_closed);

  const char* transport() const override { return "websocket"; }
  void stop(const std::string& reason) override;
  void finish() override;

 private:
  // QueuedOutbox's transport part (all on the control loop).
  void request_flush() override { flush(); }
  void read_more() override { read(); }
  std::uint64_t reading_bytes() const override { return in_.size(); }
  bool frames_wait() const override { return writing_ || !open_; }
  bool link_ready() const override { return open_; }

  // At most this much of a message is read at once.
  static constexpr std::size_t kReadPiece = 64 << 10;
  void read();
  void on_read(const boost::system::error_code& ec, std::size_t bytes);
  void flush();
  void write(std::string message, bool frame);
  void arm_watchdog() override;
  void close_socket();
  // A framed protocol message (prefix, then body) as this client's format
  // wants it; empty when it cannot be converted (logged).
  std::string to_client(std::string_view framed) const;

  websocket::stream<beast::tcp_stream> ws_;
  std::string peer_;
  Format format_ = Format::kBinary;
  bool open_ = false;  // the upgrade completed
  bool reading_ = false;
  bool socket_closed_ = false;
  std::shared_ptr<Connection::Handler> handler_;
  std::function<void(std::uint64_t)> on_closed_;
  beast::flat_buffer in_;
  std::string out_;             // the message being written
  std::uint32_t next_key_ = 0;  // frames are written key by key from here (round robin)
  net::steady_timer watchdog_;
  std::optional<net::any_io_executor> convert_;
};

}  // namespace gmr::server
