// A session: one TCP connection, its views and subscriptions, and its
// bounded outgoing queue (replies in order; frames latest-wins per subscription).
#pragma once

#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "gmr/server/view.h"
#include "server_impl.h"
#include "stream.h"

namespace gmr::server {

// Session: one TCP connection, its views and subscriptions, and its bounded
// outgoing queue (replies in order; frames latest-wins per subscription).
class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(Server::Impl& impl, tcp::socket socket, std::uint64_t id)
      : impl_(impl), socket_(std::move(socket)), id_(id), watchdog_(impl.io), read_gate_(impl.io) {
    boost::system::error_code ec;
    auto ep = socket_.remote_endpoint(ec);
    peer_ = ec ? std::string("?") : ep.address().to_string() + ":" + std::to_string(ep.port());
    do {
      token_ = impl_.rng();
    } while (token_ == 0 || impl_.tokens.count(token_));
  }

  std::uint64_t id() const { return id_; }
  bool stopped() const { return stopped_; }

  void start() {
    impl_.tokens[token_] = weak_from_this();
    socket_.set_option(tcp::no_delay(true));
    if (impl_.cfg.socket_send_buffer > 0) {
      boost::system::error_code ec;
      socket_.set_option(net::socket_base::send_buffer_size(impl_.cfg.socket_send_buffer), ec);
    }
    last_read_ = last_write_ = Clock::now();
    spdlog::info("conn {}: connected from {}", id_, peer_);
    net::co_spawn(impl_.io, read_loop(shared_from_this()), net::detached);
    arm_watchdog();
  }

  // Ends the connection: streams forget it, the socket closes. Idempotent.
  void stop(const std::string& reason);
  // Graceful: finish writing the replies queued, then stop.
  void finish() {
    close_after_flush_ = true;
    pending_frames_.clear();
    subs_.clear();
    flush();
  }

  void send(const pb::ServerMessage& m);
  // A frame of subscription `sub` (latest wins over one not yet written).
  void push_frame(std::uint32_t sub, std::uint32_t view_id, std::uint64_t stream_id,
                  const std::shared_ptr<const std::string>& body, bool via_udp);
  // The stream ended this subscription (end of motion or max_frames).
  void subscription_ended(std::uint32_t sub, std::uint64_t sent, const std::string& reason);
  void udp_registered(const udp::endpoint& ep);

  SessionStats stats() const {
    SessionStats s;
    s.id = id_;
    s.frames_sent = frames_sent_;
    s.frames_dropped = frames_dropped_;
    s.queued_bytes = queued_bytes();
    s.max_queued_bytes = max_queued_bytes_;
    s.udp_registered = udp_endpoint_.has_value();
    return s;
  }

 private:
  struct Subscription {
    std::uint32_t id = 0;
    std::uint32_t view_id = 0;
    std::shared_ptr<Stream> stream;
    bool udp = false;
    std::vector<std::string> joint_names;  // empty: every joint
    std::uint64_t dropped = 0;
  };
  struct PendingFrame {
    std::string head;
    std::shared_ptr<const std::string> body;
  };

  net::awaitable<void> read_loop(std::shared_ptr<Session> self);
  void handle(const std::string& bytes);
  pb::ServerMessage dispatch(const pb::ClientMessage& req);
  void flush();
  void arm_watchdog();
  std::uint64_t queued_bytes() const {
    std::uint64_t n = reply_bytes_ + in_flight_bytes_;
    for (const auto& [id, queue] : pending_frames_) {
      for (const auto& f : queue) n += f.head.size() + f.body->size();
    }
    return n;
  }
  void note_queue() { max_queued_bytes_ = std::max(max_queued_bytes_, queued_bytes()); }

  View& view(std::uint32_t id);
  Subscription& subscription(std::uint32_t id);
  pb::ViewInfo view_info(const View& v) const;
  void view_changed(View& v);
  std::shared_ptr<Stream> detach(Subscription& sub);
  void drop_subscription(std::uint32_t id);
  Result<std::vector<int>> resolve_joints(const View& v, const std::vector<std::string>& names) const;

  pb::ServerMessage subscribe(const pb::Subscribe& r);
  pb::ServerMessage query(const pb::QueryFrames& r);

  Server::Impl& impl_;
  tcp::socket socket_;
  std::uint64_t id_;
  std::uint64_t token_ = 0;
  std::string peer_;
  bool handshaked_ = false;
  bool stopped_ = false;
  bool close_after_flush_ = false;

  std::map<std::uint32_t, std::unique_ptr<View>> views_;
  std::uint32_t next_view_ = 1;
  std::map<std::uint32_t, Subscription> subs_;
  std::uint32_t next_sub_ = 1;

  std::deque<std::shared_ptr<const std::string>> replies_;
  std::uint64_t reply_bytes_ = 0;
  std::map<std::uint32_t, std::deque<PendingFrame>> pending_frames_;  // per subscription, oldest first
  bool writing_ = false;
  std::uint64_t in_flight_bytes_ = 0;
  std::uint64_t in_flight_reply_bytes_ = 0;
  std::vector<std::shared_ptr<const std::string>> hold_;
  std::vector<std::string> hold_heads_;
  Clock::time_point write_started_{}, last_read_{}, last_write_{};
  net::steady_timer watchdog_;
  net::steady_timer read_gate_;

  std::optional<udp::endpoint> udp_endpoint_;
  std::size_t udp_in_flight_ = 0;
  std::uint32_t udp_message_id_ = 0;

  std::uint64_t frames_sent_ = 0;
  std::uint64_t frames_dropped_ = 0;
  std::uint64_t max_queued_bytes_ = 0;
};

}  // namespace gmr::server
