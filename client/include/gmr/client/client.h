// The C++ client of gmr-server: connect, send requests, receive pushed frames
// over TCP or UDP (with reassembly). Usable from a game engine plugin: every
// call is thread-safe and blocking with a timeout; frames arrive on the
// client's own I/O thread through callbacks, which must return quickly.
//
//   auto c = gmr::client::Client::connect({.host = "127.0.0.1", .port = 7400});
//   auto view = (*c)->create_view("walk");
//   (*c)->subscribe(view->id, {.udp = true}, [](const ReceivedFrame& f) { ... });
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/skeleton/skeleton.h"
#include "gmr/stream/v1/stream.pb.h"

namespace gmr::client {

namespace pb = ::gmr::stream::v1;

struct ClientOptions {
  std::string host = "127.0.0.1";
  std::uint16_t port = 7400;
  std::string client_name = "gmr-client";
  std::chrono::milliseconds timeout{5000};  // connect, and each request's reply
  std::uint32_t max_message_bytes = 16u << 20;  // largest reply accepted
  int receive_buffer = 0;                   // SO_RCVBUF (0: system default)
};

// A view as the server last described it.
struct ViewState {
  std::uint32_t id = 0;
  std::string motion;
  std::uint32_t skeleton_version = 0;
  Skeleton skeleton;
  std::string relative_to;  // empty: world coordinates
  std::uint64_t frame_count = 0;
  double frame_time = 0.0;
  std::vector<std::string> removed;  // strip_dummies
  double join_offset_spread = 0.0;   // join
};

struct QueryResult {
  std::uint32_t skeleton_version = 0;
  std::uint32_t begin = 0, end = 0;
  std::vector<int> joints;                     // indices, in the order of the values
  std::vector<Eigen::Vector3d> positions;      // frame-major, joints.size() per frame
  std::vector<Eigen::Quaterniond> orientations;  // when asked
};

struct SubscribeOptions {
  std::uint32_t start_frame = 0;
  std::uint32_t end_frame = 0;   // exclusive; 0: the motion's end
  bool loop = false;
  double speed = 1.0;
  double rate_hz = 0.0;          // 0: the motion's own rate times speed
  bool skip_repeats = false;
  bool orientations = false;
  std::vector<std::string> joints;  // empty: every joint
  bool udp = false;
  bool float64 = false;
  bool shared = false;           // join a running stream with the same content and schedule
  std::uint64_t max_frames = 0;  // 0: no limit
};

struct ReceivedFrame {
  std::uint32_t view_id = 0;
  std::uint32_t subscription_id = 0;
  std::uint64_t stream_id = 0;
  std::uint32_t skeleton_version = 0;
  std::uint64_t frame_index = 0;
  double motion_time = 0.0;
  std::uint64_t sequence = 0;
  std::int64_t server_send_time_ns = 0;
  std::int64_t receive_time_ns = 0;  // system_clock when this client parsed it
  bool udp = false;
  std::vector<Eigen::Vector3d> positions;      // one per subscribed joint
  std::vector<Eigen::Quaterniond> orientations;  // when subscribed
};

struct SubscriptionInfo {
  std::uint32_t id = 0;
  std::uint32_t view_id = 0;
  std::uint32_t skeleton_version = 0;
  std::vector<int> joints;
  double rate_hz = 0.0;
  std::uint64_t stream_id = 0;
  bool joined_running = false;
};

using FrameCallback = std::function<void(const ReceivedFrame&)>;
using EndCallback = std::function<void(const pb::SubscriptionEnded&)>;

// Counters of what arrived; read any time.
struct ClientCounters {
  std::uint64_t frames_tcp = 0;
  std::uint64_t frames_udp = 0;
  std::uint64_t udp_incomplete_dropped = 0;  // messages with a lost fragment
  std::uint64_t udp_malformed = 0;
};

class Client {
 public:
  // Connects and says Hello. Fails with the reason (refused, timed out,
  // protocol version mismatch, ...).
  static Result<std::unique_ptr<Client>> connect(const ClientOptions& options);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  const pb::HelloReply& hello() const;
  bool connected() const;
  // Closes the connection; pending requests fail. Idempotent.
  void close();

  // Requests. A server Error comes back as an Error whose message starts with
  // its code ("NOT_FOUND: unknown motion 'x'").
  Result<std::vector<pb::MotionInfo>> list_motions();
  Result<Skeleton> skeleton(const std::string& motion);
  Result<ViewState> create_view(const std::string& motion);
  Status close_view(std::uint32_t view);
  Result<ViewState> shift_root(std::uint32_t view, const std::string& joint);
  Result<ViewState> split(std::uint32_t view, const std::string& joint);
  Result<ViewState> join(std::uint32_t view, const std::string& root);
  Result<ViewState> set_roots(std::uint32_t view, const std::vector<std::string>& roots);
  Result<ViewState> strip_dummies(std::uint32_t view);
  Result<ViewState> set_coordinates(std::uint32_t view, const std::string& relative_to);  // "" = world
  Result<QueryResult> query(std::uint32_t view, std::uint32_t begin, std::uint32_t end, bool orientations = false,
                            const std::vector<std::string>& joints = {});
  // Frames start after the reply; `on_frame` runs on the I/O thread (for UDP
  // frames too), `on_end` when the server ends the subscription. With
  // options.udp the client first registers its UDP endpoint.
  Result<SubscriptionInfo> subscribe(std::uint32_t view, const SubscribeOptions& options, FrameCallback on_frame,
                                     EndCallback on_end = {});
  Status unsubscribe(std::uint32_t subscription);
  Status pause(std::uint32_t subscription);
  Status resume(std::uint32_t subscription);
  Status seek(std::uint32_t subscription, std::uint32_t frame);
  Result<pb::Stats> stats();
  // Registers the UDP endpoint now (subscribe does it when needed).
  Status register_udp();

  // Any request; the reply as it came (an Error reply is a value here).
  Result<pb::ServerMessage> request(pb::ClientMessage message);

  ClientCounters counters() const;

  struct Impl;

 private:
  Client() = default;
  std::shared_ptr<Impl> impl_;
};

}  // namespace gmr::client
