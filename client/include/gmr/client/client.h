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
#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/skeleton/skeleton.h"
#include "gmr/view/conventions.h"
#include "gmr/view/engine_pose.h"
#include "gmr/wire/frame_values.h"

// The public types are plain structs: a program using the client needs no
// protobuf header (gmr::wire, linked by gmr::client, speaks the protocol).
namespace boost::asio {
class io_context;
}

namespace gmr::client {

// I/O threads that many clients share (by default each Client runs its own
// thread): a load tester or an engine with hundreds of connections creates
// one EventLoop with a few threads and passes it in ClientOptions::loop.
// Each client's handlers still run one at a time (a strand per client), and
// its callbacks run on one of the loop's threads. Close the clients before
// the EventLoop goes.
class EventLoop {
 public:
  explicit EventLoop(unsigned threads = 1);
  // The caller's own Asio io_context, which the caller runs (on as many
  // threads as it likes) and keeps alive while clients use it.
  explicit EventLoop(boost::asio::io_context& io);
  ~EventLoop();
  EventLoop(const EventLoop&) = delete;
  EventLoop& operator=(const EventLoop&) = delete;
  unsigned threads() const;  // its own threads; 0 on the caller's io_context

 private:
  friend class Client;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct ClientOptions {
  std::string host = "127.0.0.1";
  std::uint16_t port = 7400;
  std::string client_name = "gmr-client";
  std::chrono::milliseconds timeout{5000};      // connect, and each request's reply
  std::uint32_t max_message_bytes = 16u << 20;  // largest reply accepted
  int receive_buffer = 0;                       // SO_RCVBUF (0: system default)
  // Requests written to the socket but not yet taken by the kernel: a request
  // that would take them past this many bytes fails at once ("write queue
  // full", ErrorKind::kResourceExhausted) instead of queueing without bound
  // behind a server that stopped reading. An empty queue takes any request.
  std::size_t max_write_queue_bytes = 4u << 20;
  // A token from the server's auth file (docs/security.md); empty: connect
  // anonymously. It is a password: send it over TLS or loopback only.
  std::string auth_token;
  // TLS (docs/security.md). The server's certificate must chain to ca_file
  // (PEM; empty: the system's trust store) and name server_name (empty: host).
  struct Tls {
    bool enabled = false;
    std::string ca_file;
    std::string server_name;
  } tls;
  // Shared I/O threads (EventLoop); null: this client runs its own thread.
  std::shared_ptr<EventLoop> loop;
};

// What the connection may do (the server's auth file, docs/security.md).
enum class Role : std::uint8_t {
  kUnknown,  // a server that does not say
  kRead,     // list, skeletons, views and their viewpoint, queries, subscriptions
  kControl,  // also structural view edits and server statistics
  kPublish,  // also live sources (publish)
};

// What the server said in its Hello reply.
struct ServerHello {
  std::uint32_t protocol_version = 0;
  std::string server_name;
  std::array<std::uint8_t, 16> udp_token{};  // for UDP registration (register_udp does it)
  std::uint16_t udp_port = 0;                // 0: no UDP
  std::uint32_t max_message_bytes = 0;
  std::uint32_t heartbeat_interval_ms = 0;
  std::uint32_t idle_timeout_ms = 0;
  Role role = Role::kUnknown;
  // The server's clock minus this client's (system clocks, nanoseconds),
  // estimated from the Hello round trip (0 for a server that does not say):
  // what frames' ages are measured with.
  std::int64_t clock_offset_ns = 0;
  bool tls = false;  // the connection speaks TLS
};

// One motion of the server's library.
struct MotionInfo {
  std::string name;
  std::uint32_t joint_count = 0;
  std::uint64_t frame_count = 0;
  double frame_time = 0.0;
  std::string source;            // the file it came from, or "builtin"
  double metres_per_unit = 0.0;  // the motion's unit in metres; 0: unknown
  std::uint32_t version = 0;     // a library motion's: one more each time the server reloads it (0: not said)
};

// A view as the server last described it.
struct ViewState {
  std::uint32_t id = 0;
  std::string motion;
  std::uint32_t skeleton_version = 0;
  Skeleton skeleton;
  RestPose rest;            // each joint's rest translation and rotation as an engine bone (motion's conventions)
  std::string relative_to;  // empty: world coordinates
  std::uint64_t frame_count = 0;
  double frame_time = 0.0;
  std::vector<std::string> removed;  // strip_dummies
  double join_offset_spread = 0.0;   // join
};

struct QueryResult {
  std::uint32_t skeleton_version = 0;
  std::uint32_t begin = 0, end = 0;
  std::vector<int> joints;                          // indices, in the order of the values
  std::vector<Eigen::Vector3d> positions;           // frame-major, joints.size() per frame
  std::vector<Eigen::Quaterniond> orientations;     // when asked
  std::vector<Eigen::Quaterniond> local_rotations;  // when asked: relative to the parent's frame
  std::vector<Eigen::Vector3d> local_translations;
  double metres_per_unit = 0.0;  // the positions' unit in metres; 0: unknown (the motion's own)
};

struct QueryOptions {
  bool orientations = false;
  bool local_transforms = false;    // each joint's rotation and translation relative to its parent
  std::vector<std::string> joints;  // empty: every joint
  Conventions conventions;
};

struct SubscribeOptions {
  std::uint32_t start_frame = 0;
  std::uint32_t end_frame = 0;  // exclusive; 0: the motion's end
  bool loop = false;
  double speed = 1.0;
  double rate_hz = 0.0;  // 0: the motion's own rate times speed
  bool skip_repeats = false;
  bool orientations = false;
  bool local_transforms = false;    // each joint's rotation and translation relative to its parent (engine bones)
  std::vector<std::string> joints;  // empty: every joint
  bool udp = false;
  bool float64 = false;
  bool shared = false;  // join a running stream with the same content and schedule
  // Frames from the server's multicast group (a shared stream sent once to
  // every subscriber on the network; the server must have --multicast-group).
  // The client joins the group on the interface it reaches the server by.
  bool multicast = false;
  std::uint64_t max_frames = 0;  // 0: no limit
  // Start held at start_frame: that one frame comes, then nothing until
  // resume() (not for multicast).
  bool paused = false;
  // Frames older than this are never delivered: the server drops those that
  // waited longer in its queue, this client those that arrive older (after a
  // stall, the kernel's buffers still hold them); both are counted. Zero: no
  // bound. docs/protocol.md, "Staleness".
  std::chrono::milliseconds max_staleness{100};
  Conventions conventions;  // an engine's axes and unit (gmr/view/conventions.h); default: the motion's own
};

// A frame as it arrived: ids, frame index and motion time, sequence,
// server send time, one position per subscribed joint and, when subscribed,
// one orientation each (gmr::wire::FrameValues), plus how it came.
struct ReceivedFrame : wire::FrameValues {
  std::int64_t receive_time_ns = 0;  // system_clock when this client parsed it
  bool udp = false;
};

struct SubscriptionInfo {
  std::uint32_t id = 0;
  std::uint32_t view_id = 0;
  std::uint32_t skeleton_version = 0;
  std::vector<int> joints;
  double rate_hz = 0.0;
  std::uint64_t stream_id = 0;
  bool joined_running = false;
  Skeleton skeleton;            // the view's, as the frames' values follow it
  RestPose rest;                // in the subscription's conventions
  std::string relative_to;      // empty: world coordinates
  std::string multicast_group;  // multicast subscriptions: "group:port" the frames come from
  // The unit of the frames' positions in metres (the conventions' when the
  // motion's unit is known); 0: unknown, the motion's own units.
  double metres_per_unit = 0.0;
};

// The server ended a subscription (end of motion, max_frames, a view change
// that removed a subscribed joint).
struct SubscriptionEnd {
  std::uint32_t subscription_id = 0;
  std::uint64_t frames_sent = 0;
  std::uint64_t frames_dropped = 0;  // this client was slow (frames it did not read in time)
  std::string reason;
  std::uint64_t frames_skipped = 0;  // the server was late (ticks skipped to catch up)
  std::uint64_t frames_stale = 0;    // of frames_dropped, those the server held past max_staleness
};

// The server's counters (GetStats); the frames_sent .. max_queued_bytes are
// this connection's.
struct ServerCounters {
  std::uint32_t connections = 0;
  std::uint32_t streams = 0;
  std::uint64_t frames_computed = 0;        // forward-kinematics runs for streams
  std::uint64_t frames_computed_float = 0;  // of those, by the float path
  std::uint64_t frames_encoded = 0;         // encodings (one per stream tick)
  std::uint64_t frames_sent = 0;
  std::uint64_t frames_dropped = 0;
  std::uint64_t frames_skipped = 0;        // this connection: the server was late
  std::uint64_t frames_skipped_total = 0;  // all streams
  std::uint64_t queued_bytes = 0;
  std::uint64_t max_queued_bytes = 0;
  double committed_frames_per_second = 0;         // all subscriptions' rates together
  double send_budget = 0;                         // what the server admits (0: no limit)
  std::uint64_t subscriptions_refused = 0;        // for the send budget
  std::uint32_t live_sources = 0;                 // being published now
  std::uint64_t live_frames_received = 0;         // published frames the server accepted
  std::uint64_t live_frames_refused = 0;          // and refused
  std::uint64_t live_frames_over_rate = 0;        // and dropped: faster than the source's declared rate
  std::uint64_t live_edit_replays = 0;            // live views' edits replayed, once per frame for equal edits
  std::uint64_t live_marker_points_missing = 0;   // marker points live marker sources' frames lacked
  std::uint64_t live_marker_parts_held = 0;       // and part poses held for want of them
  std::uint64_t live_marker_points_outliers = 0;  // and points left out as outliers (swapped or stray labels)
  std::uint64_t live_marker_frames_unsolved = 0;  // frames left unsolved (a part not fitted yet)
  std::uint64_t multicast_frames_sent = 0;        // to the multicast group, once each
  std::uint64_t frames_sent_total = 0;            // all connections, open and closed (one request's snapshot)
  std::uint64_t frames_dropped_total = 0;         // all connections, open and closed
  std::uint32_t io_threads = 0;                   // the server's I/O threads (0: a server that does not say)
  std::uint32_t io_thread = 0;                    // this connection's (0: the control loop)
};

// A live source this client publishes (docs/protocol.md, "Live sources").
struct PublishOptions {
  std::string name;               // its name in the server's list
  double frame_time = 1.0 / 120;  // seconds per frame: the rate subscribers are told
  double metres_per_unit = 0.0;   // the motion's unit in metres; 0: unknown
  bool record = false;            // the server writes it to its --record-dir when it ends
};

// A live source of labelled markers (docs/protocol.md, "Live markers"): the
// server solves each frame into `model`'s skeleton, and serves it once the
// first `calibration_seconds` of frames calibrated the model.
struct MarkerPublishOptions {
  std::string name;
  double frame_time = 1.0 / 120;
  std::string model = "cmu41";  // a built-in skeleton model
  double calibration_seconds = 2.0;
  std::string units = "mm";  // of the coordinates: mm, cm, m or in
  bool record = false;       // ask the server to record the solved skeleton (its --record-dir) as .gmrb
};

struct Publication {
  std::uint32_t id = 0;  // for publish_frame and unpublish
  std::string motion;
  std::string recording;  // with PublishOptions::record: the file the server will write
};

// Runs on the client's I/O thread for each frame; the ReceivedFrame is the
// subscription's own, decoded into again for the next frame, so it is valid
// during the call only (copy what is kept).
using FrameCallback = std::function<void(const ReceivedFrame&)>;
using EndCallback = std::function<void(const SubscriptionEnd&)>;

// A running subscription's view changed structure or coordinate frame: the
// skeleton of the frames that follow (their skeleton_version), sent before
// the first of them.
struct SkeletonChange {
  std::uint32_t subscription_id = 0;
  std::uint32_t view_id = 0;
  std::uint32_t skeleton_version = 0;
  Skeleton skeleton;
  RestPose rest;            // in the subscription's conventions
  std::vector<int> joints;  // indices into skeleton of each frame's values, in order
  std::string relative_to;  // empty: world coordinates
};
using SkeletonCallback = std::function<void(const SkeletonChange&)>;

// Counters of what arrived; read any time.
struct ClientCounters {
  std::uint64_t frames_tcp = 0;
  std::uint64_t frames_udp = 0;
  std::uint64_t udp_incomplete_dropped = 0;  // messages with a lost fragment
  std::uint64_t udp_malformed = 0;
  std::uint64_t frames_malformed = 0;  // frames whose values did not decode (dropped)
  std::uint64_t frames_stale = 0;      // frames that arrived older than their max_staleness (dropped)
  // Frames of another skeleton version than the subscription's latest
  // (Subscribed, then each SkeletonChange): dropped, so a FrameCallback
  // only gets frames whose values follow the skeleton it was last given.
  std::uint64_t frames_other_skeleton = 0;
};

class Client {
 public:
  // Connects and says Hello. Fails with the reason (refused, timed out,
  // protocol version mismatch, ...).
  static Result<std::unique_ptr<Client>> connect(const ClientOptions& options);
  ~Client();
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;

  const ServerHello& hello() const;
  bool connected() const;
  // Closes the connection; pending requests fail. Idempotent.
  void close();

  // Requests. A server Error comes back as an Error whose message starts with
  // its code ("NOT_FOUND: unknown motion 'x'").
  Result<std::vector<MotionInfo>> list_motions();
  Result<Skeleton> skeleton(const std::string& motion);
  // The motion's rest pose as engine bones, in `conventions`.
  Result<RestPose> rest_pose(const std::string& motion, const Conventions& conventions = {});
  Result<ViewState> create_view(const std::string& motion);
  Status close_view(std::uint32_t view);
  Result<ViewState> shift_root(std::uint32_t view, const std::string& joint);
  Result<ViewState> split(std::uint32_t view, const std::string& joint);
  Result<ViewState> join(std::uint32_t view, const std::string& root);
  Result<ViewState> set_roots(std::uint32_t view, const std::vector<std::string>& roots);
  Result<ViewState> strip_dummies(std::uint32_t view);
  Result<ViewState> set_coordinates(std::uint32_t view, const std::string& relative_to);  // "" = world
  // The view's motion put on another humanoid rig (docs/retarget.md): its
  // skeleton (BVH-like: post-rotation), the channel values of a pose it stands
  // in when its rest pose does not (empty: the rest pose), and role -> joint
  // maps (empty: built-in namings), and the rig's unit in metres (0: the
  // motion's). Running subscriptions get the new skeleton.
  Result<ViewState> retarget(std::uint32_t view, const Skeleton& rig, const std::vector<double>& reference = {},
                             const std::map<std::string, std::string>& rig_map = {},
                             const std::map<std::string, std::string>& source_map = {},
                             double rig_metres_per_unit = 0.0);
  Result<QueryResult> query(std::uint32_t view, std::uint32_t begin, std::uint32_t end, bool orientations = false,
                            const std::vector<std::string>& joints = {}, const Conventions& conventions = {});
  Result<QueryResult> query(std::uint32_t view, std::uint32_t begin, std::uint32_t end, const QueryOptions& options);
  // Frames start after the reply; `on_frame` runs on the I/O thread (for UDP
  // frames too), `on_end` when the server ends the subscription. With
  // options.udp the client first registers its UDP endpoint.
  // `on_skeleton` runs on the I/O thread when the view's skeleton version
  // changes, before the first frame of the new version. `on_frame` gets only
  // frames of the version it was last told of (the reply's, then each
  // on_skeleton's); others are dropped and counted (frames_other_skeleton).
  Result<SubscriptionInfo> subscribe(std::uint32_t view, const SubscribeOptions& options, FrameCallback on_frame,
                                     EndCallback on_end = {}, SkeletonCallback on_skeleton = {});
  Status unsubscribe(std::uint32_t subscription);
  Status pause(std::uint32_t subscription);
  Status resume(std::uint32_t subscription);
  Status seek(std::uint32_t subscription, std::uint32_t frame);
  Result<ServerCounters> stats();
  // Registers the UDP endpoint now (subscribe does it when needed).
  Status register_udp();

  // Live sources (a 'publish' token). publish announces `skeleton`, whose
  // channels are a pre-rotation (GMR) motion's (to_pre_rotation converts a
  // BVH or ASF/AMC motion), and returns the publication. Every frame is
  // then `values`: skeleton.channel_count() numbers, the motion's frame
  // layout. publish_frame queues the frame without waiting (it fails only
  // when the write queue is full); a frame the server refuses comes back in
  // take_errors(). unpublish ends the source; closing the client ends them all.
  Result<Publication> publish(const Skeleton& skeleton, const PublishOptions& options);
  Status publish_frame(std::uint32_t publication, std::span<const double> values);
  // Labelled markers: publish_markers names them once; each
  // publish_marker_frame gives x, y, z per marker in that order, NaN for a
  // marker the frame lacks (sent as missing).
  Result<Publication> publish_markers(std::span<const std::string> marker_names, const MarkerPublishOptions& options);
  Status publish_marker_frame(std::uint32_t publication, std::span<const double> positions);
  Status unpublish(std::uint32_t publication);
  // Errors the server sent for requests that get no reply (refused
  // PublishFrame), oldest first, and forgets them; at most 64 are kept.
  std::vector<std::string> take_errors();

  // Any request, as a serialized gmr.stream.v1.ClientMessage (its
  // request_id is set here); the reply as serialized ServerMessage bytes, as
  // it came (an Error reply is a value here). For requests this API does not
  // wrap yet.
  Result<std::string> request_raw(std::string_view client_message);

  ClientCounters counters() const;

  struct Impl;

 private:
  Client() = default;
  std::shared_ptr<Impl> impl_;
};

}  // namespace gmr::client
