// RecordingOutbox: an Outbox that keeps what it is given (replies and
// frames as ServerMessages), to run a RequestHandler without sockets; and
// RecordedSession, a handler on one, that has said Hello.
#pragma once

#include <gtest/gtest.h>

#include <deque>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "gmr/stream/v1/stream.pb.h"
#include "gmr/wire/framing.h"
#include "requests/request_handler.h"
#include "transport/outbox.h"

namespace gmr::test {

namespace pb = ::gmr::stream::v1;  // as in net_test_util.h

class RecordingOutbox final : public server::Outbox {
 public:
  explicit RecordingOutbox(std::uint64_t id = 7) : id_(id) {}
  std::uint64_t id() const override { return id_; }
  bool stopped() const override { return false; }
  bool closing() const override { return closing_; }
  void send(std::string framed) override { replies.push_back(unframe(framed)); }
  bool push_frame(std::uint32_t key, const wire::FrameHead& head, std::shared_ptr<const std::string> body,
                  std::chrono::steady_clock::duration, std::chrono::steady_clock::time_point) override {
    frames.push_back(unframe(std::string(head.view()) + *body));
    keys.push_back(key);
    return true;
  }
  void discard_frames(std::uint32_t) override {}
  void send_frames_now(std::uint32_t) override {}
  std::uint64_t end_frames(std::uint32_t) override { return 0; }
  void close_after_reply() override { closing_ = true; }
  void hold_reading(bool hold) override { reading_held = hold; }
  void stop(const std::string&) override { closing_ = true; }
  void finish() override { closing_ = true; }
  void count_udp_frame_sent(std::chrono::steady_clock::duration) override {}
  void count_udp_frame_dropped() override {}
  void count_frame_dropped(std::uint64_t) override {}
  void count_frame_skipped(std::uint64_t) override {}
  server::ConnectionCounters counters() const override { return {}; }

  std::deque<pb::ServerMessage> replies;
  std::vector<pb::ServerMessage> frames;
  std::vector<std::uint32_t> keys;
  bool reading_held = false;  // the handler's last hold_reading

 private:
  static pb::ServerMessage unframe(const std::string& framed) {
    pb::ServerMessage m;
    EXPECT_GE(framed.size(), wire::kLengthPrefixBytes);
    if (framed.size() < wire::kLengthPrefixBytes) return m;
    EXPECT_EQ(wire::read_length_prefix(std::span<const std::uint8_t, wire::kLengthPrefixBytes>(
                  reinterpret_cast<const std::uint8_t*>(framed.data()), wire::kLengthPrefixBytes)),
              framed.size() - wire::kLengthPrefixBytes);
    EXPECT_TRUE(m.ParseFromString(framed.substr(wire::kLengthPrefixBytes)));
    return m;
  }
  std::uint64_t id_;
  bool closing_ = false;
};

// A session of the server's parts (no socket): its handler, past Hello, and
// what it was sent.
struct RecordedSession {
  RecordedSession(server::Services& services, std::uint64_t id)
      : box(std::make_shared<RecordingOutbox>(id)), handler(std::make_shared<server::RequestHandler>(services, box)) {
    handler->start();
    pb::ClientMessage hello;
    hello.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
    EXPECT_TRUE(ask(hello).has_hello());
  }

  // Its reply to `m` (the last message sent; the others stay in box->replies).
  pb::ServerMessage ask(const pb::ClientMessage& m) {
    const std::size_t before = box->replies.size();
    handler->on_message(m.SerializeAsString());
    EXPECT_GT(box->replies.size(), before) << "no reply";
    if (box->replies.size() == before) return {};
    pb::ServerMessage r = box->replies.back();
    box->replies.pop_back();
    return r;
  }
  // A view of library motion `motion`: its id (0, and a failure, when refused).
  std::uint32_t create_view(const std::string& motion) {
    pb::ClientMessage m;
    m.mutable_create_view()->set_motion(motion);
    const pb::ServerMessage r = ask(m);
    EXPECT_TRUE(r.has_view()) << r.DebugString();
    return r.view().view_id();
  }
  // The SubscriptionEnded it was sent for `subscription`, if any.
  std::optional<pb::SubscriptionEnded> ended(std::uint32_t subscription = 1) const {
    for (const auto& r : box->replies) {
      if (r.has_subscription_ended() && r.subscription_ended().subscription_id() == subscription) {
        return r.subscription_ended();
      }
    }
    return std::nullopt;
  }

  std::shared_ptr<RecordingOutbox> box;
  std::shared_ptr<server::RequestHandler> handler;
  std::uint64_t max_frames = 0;  // what the test asked for
};

}  // namespace gmr::test
