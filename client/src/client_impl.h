// Client::Impl and what the client's source files share (private to
// gmr::client). The client is split by concern: client.cpp (connecting,
// closing, the event loop and the request API), link.cpp (the TCP link:
// writes, reads, replies, heartbeats, TLS), delivery.cpp (frames and pushes
// handed to subscriptions), udp_receive.cpp (UDP frames, registration
// challenges, multicast), subscribe.cpp (subscriptions), publish.cpp
// (live sources).
#pragma once

#include "gmr/client/client.h"

#include <algorithm>
#include <atomic>
#include <boost/asio.hpp>
#include <boost/asio/ssl.hpp>
#include <charconv>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <future>
#include <limits>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include "gmr/stream/v1/stream.pb.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/frames.h"
#include "gmr/wire/framing.h"
#include "gmr/asio/tls_socket.h"
#include "gmr/wire/udp.h"

namespace gmr::client {

namespace pb = ::gmr::stream::v1;

namespace net = boost::asio;
using tcp = net::ip::tcp;
using udp = net::ip::udp;

inline std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// A native convention is sent as nothing at all (what an old client sends).
void to_proto(const Conventions& c, pb::Conventions& out);
// A reply carrying a view as a ViewState, or its error.
Result<ViewState> to_view(Result<pb::ServerMessage> r);
Status to_status(Result<pb::ServerMessage> r);

// The io_context a client's handlers run on: its own (one thread, started
// by connect()) or an EventLoop's, shared with other clients.
struct Loop {
  Loop() : owned(std::make_unique<net::io_context>()), io(*owned) {}
  explicit Loop(net::io_context& caller) : io(caller) {}
  std::unique_ptr<net::io_context> owned;  // null: the caller's
  net::io_context& io;
  // True on a thread inside io.run() (a callback): close() must not wait there.
  bool runs_here() const { return io.get_executor().running_in_this_thread(); }
};

struct EventLoop::Impl {
  explicit Impl(std::shared_ptr<Loop> l) : loop(std::move(l)) {}
  std::shared_ptr<Loop> loop;
  std::optional<net::executor_work_guard<net::io_context::executor_type>> guard;
  std::vector<std::thread> threads;
};

struct Client::Impl : std::enable_shared_from_this<Impl> {
  explicit Impl(std::shared_ptr<Loop> l) : loop(std::move(l)), io(loop->io), strand(net::make_strand(io)) {}

  ClientOptions options;
  std::shared_ptr<Loop> loop;
  net::io_context& io;
  // Every handler of this client runs on its strand, so a loop with several
  // threads never runs two of them at once.
  net::strand<net::io_context::executor_type> strand;
  bool own_loop = true;
  std::atomic<bool> closed{false};
  std::optional<net::ssl::context> tls_context;  // options.tls.enabled; outlives the socket
  asio::TlsSocket socket{net::any_io_executor(strand)};
  udp::socket udp_socket{strand};
  std::atomic<bool> udp_open{false};  // the UDP socket opened (on the strand) at connect
  udp::endpoint server_udp;
  net::steady_timer heartbeat{strand};
  std::thread thread;             // own loop only
  std::future<void> thread_done;  // ready when the own loop's thread left io.run()
  static constexpr auto kCloseGrace = std::chrono::milliseconds(900);
  // Own loop: keeps run() going until close(); then the loop ends once every
  // handler has completed (never io.stop(): a handler left queued would keep
  // Impl alive).
  std::optional<net::executor_work_guard<net::io_context::executor_type>> guard;
  ServerHello hello;

  std::atomic<bool> open{false};
  std::atomic<std::uint64_t> next_request{1};
  // A reply, or nullopt when the connection failed first (close_reason says
  // why). Not an exception: an exception object shared by two threads is
  // freed by whichever releases it last, which ThreadSanitizer cannot see
  // through the uninstrumented libstdc++ and reports as a race.
  struct Pending {
    std::promise<std::optional<pb::ServerMessage>> promise;
    std::function<void(const pb::ServerMessage&)> on_reply;  // runs on the I/O thread before the promise is set
  };
  mutable std::mutex mutex;
  std::map<std::uint64_t, Pending> pending;
  struct Sub {
    FrameCallback on_frame;
    EndCallback on_end;
    SkeletonCallback on_skeleton;
    std::int64_t max_age_ns = 0;  // 0: no staleness bound
    std::uint64_t stream_id = 0;  // multicast: frames carry the stream's id, not the subscription's
    bool multicast = false;
    // The skeleton version the callbacks were last told of (the Subscribed
    // reply, then each SkeletonChanged). A frame of another version is not
    // that skeleton's (a UDP frame of the new version can overtake its
    // SkeletonChanged, a queued TCP frame of the old one can follow it): it
    // is dropped and counted, so on_frame only sees frames of the skeleton
    // it knows. Under mutex.
    std::uint32_t skeleton_version = 0;
    // The values each frame of that version carries (one per subscribed
    // joint; 0: not stated, no check). A frame with another count is
    // malformed: dropped and counted, never handed on. Under mutex.
    std::size_t values = 0;
    // Frames that came for it, whatever became of them (under mutex), and
    // its end notice when that came before frames it counts (a UDP frame
    // can be overtaken by the TCP notice): held until they are all here or
    // kEndGrace passed, so on_end is the last callback and the last frames
    // are not lost.
    std::uint64_t arrived = 0;
    std::optional<SubscriptionEnd> ending{};
    std::shared_ptr<net::steady_timer> ending_timer{};
    // Each frame is decoded into this one (on the strand, one at a time), so
    // a frame costs no allocation once its lists have grown.
    ReceivedFrame frame{};
  };
  static constexpr auto kEndGrace = std::chrono::milliseconds(100);
  // The multicast group's socket (the first multicast subscription opens it).
  std::optional<udp::socket> multicast_socket;
  udp::endpoint multicast_sender;
  std::array<char, 2048> multicast_buffer{};
  wire::Reassembler multicast_reassembler;
  std::map<std::uint32_t, std::shared_ptr<Sub>> subs;
  // A UDP frame can overtake the TCP reply to its Subscribe: frames for an
  // unknown subscription wait here (bounded) while a Subscribe is in flight.
  int subscribes_in_flight = 0;
  std::deque<std::pair<pb::ServerMessage, bool>> early_frames;
  static constexpr std::size_t kMaxEarlyFrames = 256;
  std::string close_reason;
  bool udp_registered = false;
  std::condition_variable udp_cv;
  ClientCounters counters;
  std::deque<std::string> async_errors;  // for requests that get no reply
  static constexpr std::size_t kMaxAsyncErrors = 64;

  // I/O-thread state
  std::deque<std::string> write_queue;
  std::atomic<std::size_t> write_queue_bytes{0};  // also read by callers of send()
  bool writing = false;
  // What the server sent and was not handled yet: in_[0, in_end_), whole
  // messages handled as they arrive, so one read takes what came (many
  // frames at once under load) rather than two reads a message.
  std::string in_;
  std::size_t in_end_ = 0;
  std::array<char, 2048> udp_buffer{};
  udp::endpoint udp_sender;
  wire::Reassembler reassembler;

  // Queues `framed` for the socket; false (nothing queued) when it would take
  // a non-empty queue past options.max_write_queue_bytes.
  bool send(std::string framed);
  void write_next();
  // Reads what the server sent, and handles each whole message.
  void read_more();
  // Handles the whole messages in in_ and keeps the rest; false when the link failed.
  bool take_messages();
  void read_udp();
  // Joins `group` (address:port) on the interface of the TCP connection; on the strand.
  Status join_multicast(const std::string& group);
  void read_multicast();
  void arm_heartbeat();

  // A held end notice (Sub::ending) is given to on_end once every frame it
  // counts arrived, or (`now`) when its grace is over.
  void finish_ending(std::uint32_t id, const std::shared_ptr<Sub>& sub, bool now);

  void on_message(const pb::ServerMessage& m, bool via_udp);
  // A whole ServerMessage as it came: a frame in the form servers write it is
  // read in place (wire::read_frame_message), anything else parsed by
  // protobuf and handed to on_message (over UDP, only frames). False when it
  // does not parse.
  bool take_message(std::string_view message, bool via_udp);

  // Hands a frame to its subscription's on_frame (or drops and counts it, or
  // holds it while a Subscribe is in flight: `held` is the frame as a
  // message, made only then); the subscription it was for, or null.
  std::shared_ptr<Sub> deliver_frame(const wire::FrameFields& f, bool via_udp,
                                     const std::function<pb::ServerMessage()>& held);

  // A reply to a request (its caller's promise), or a push (an end, a new
  // skeleton, the UDP registration, an error).
  void on_answer(const pb::ServerMessage& m);
  void on_push(const pb::ServerMessage& m);

  // Ends the connection once (the first reason is kept); pending requests
  // get no reply.
  void fail(const std::string& reason);

  // Why the joint indices a server gave for a subscription (Subscribed,
  // SkeletonChanged) cannot be used with its skeleton of `skeleton_size`
  // joints (0: none sent); empty when they can.
  static std::string bad_joints(const google::protobuf::RepeatedField<std::uint32_t>& joints,
                                std::size_t skeleton_size);
  // Closes every socket and cancels every timer, whether or not fail() ran
  // before (a socket opened after it, by connect() or a multicast join, is
  // closed too): afterwards no handler of this client waits for anything. On
  // the strand.
  void shut();

  Result<pb::ServerMessage> call(pb::ClientMessage m, std::function<void(const pb::ServerMessage&)> on_reply = {});

  // The TLS handshake on the connected socket, within options.timeout: the
  // server's certificate must chain to the CA and name the server.
  Status start_tls(const std::string& where);

  // A reply of the expected kind, or the server's Error as an Error.
  Result<pb::ServerMessage> expect(pb::ClientMessage m, pb::ServerMessage::BodyCase expected,
                                   std::function<void(const pb::ServerMessage&)> on_reply = {});
};

}  // namespace gmr::client
