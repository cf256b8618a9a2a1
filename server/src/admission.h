// Admission: who may connect and what the connected may hold. The
// per-address and total connection limits, the connections still waiting
// for their Hello, the registry of open connections (and the counters of
// closed ones), the bytes every connection buffers, the frames per second
// subscriptions commit against the send budget, and the motion bytes views
// own. On the control loop, but `buffers`, which connections on every I/O
// thread settle into.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "gmr/server/config.h"
#include "gmr/server/server.h"
#include "transport/link.h"
#include "transport/outbox.h"

namespace gmr::server {

// What a client's session shows of itself to snapshots and metrics.
class SessionInfo {
 public:
  virtual ~SessionInfo() = default;
  virtual std::size_t view_count() const = 0;
  // Subscriptions whose frames go through the connection, and over UDP.
  virtual std::pair<std::size_t, std::size_t> subscription_count() const = 0;
  virtual bool has_udp_endpoint() const = 0;
};

class Admission {
 public:
  explicit Admission(const ServerConfig& cfg);

  // The bytes all connections hold, against cfg.max_buffered_bytes.
  BufferBudget buffers;

  // --- Connections -------------------------------------------------------
  struct Entry {
    std::weak_ptr<Outbox> connection;
    std::weak_ptr<SessionInfo> session;
    std::string address;           // the client's IP address
    std::size_t lane = 0;          // its I/O thread (WebSocket clients are on the control loop)
    bool counted_on_lane = false;  // IoThreads::assign counted it (TCP)
  };
  // Why a new connection from `address` is refused (empty: admit it). May
  // close the oldest connection still waiting for its Hello to make room.
  std::string admit(const std::string& address);
  // A connection refused for `why` (counted; logged at a bounded rate when `log`).
  void refused(const std::string& why, bool log);
  std::uint64_t next_id() { return next_id_++; }
  // Registers an accepted connection; it waits for its Hello from now on.
  Entry& add(const std::shared_ptr<Outbox>& connection, std::weak_ptr<SessionInfo> session, const std::string& address);
  // Connection `id` said Hello (the pending cap no longer counts it).
  void established(std::uint64_t id) { pending_hello_.erase(id); }
  // Forgets connection `id`, which closed: its counters join the closed
  // ones. Returns its entry (nullopt: unknown).
  std::optional<Entry> remove(std::uint64_t id);
  const std::map<std::uint64_t, Entry>& connections() const { return connections_; }
  Entry* find(std::uint64_t id) {
    auto it = connections_.find(id);
    return it == connections_.end() ? nullptr : &it->second;
  }
  // Frames and bytes of every connection, open or closed, by transport.
  std::map<std::string, ConnectionCounters, std::less<>> totals_by_transport() const;
  ConnectionCounters totals() const;
  const std::map<std::string, std::uint64_t, std::less<>>& accepted() const { return accepted_; }
  std::uint64_t connections_refused() const { return connections_refused_; }
  // What the open connections hold: connections by transport, views, and
  // subscriptions by the transport their frames take.
  struct Holdings {
    std::map<std::string, std::size_t, std::less<>> connections;
    std::size_t views = 0;
    std::map<std::string, std::size_t, std::less<>> subscriptions;
  };
  Holdings holdings() const;
  // Each open connection's figures (Server::stats).
  std::vector<SessionStats> session_stats() const;
  // Each open connection's p99 frame wait (seconds, WaitHistogram), for those
  // that were sent frames, in ascending order.
  std::vector<double> frame_wait_p99s() const;

  // --- Hello ---------------------------------------------------------------
  // A Hello refused for its token; true when it may be logged now (then
  // `suppressed` says how many were not).
  bool hello_refused(std::uint64_t& suppressed);
  std::uint64_t hellos_refused() const { return hellos_refused_; }
  // Refused Hellos by address (IPv6 by /64, address_group): the first
  // kFreeAuthFailures cost nothing; after them each makes the address wait
  // before its next Hello is checked at all, 250 ms doubling up to 30 s (a
  // token guesser gets a few hundred tries an hour, not 9,000 a second). A
  // Hello that passes clears the address; one quiet for a minute after its
  // wait starts afresh. How long `address` must still wait (nullopt: none).
  std::optional<Clock::duration> auth_wait(const std::string& address) const;
  void auth_failed(const std::string& address);
  void auth_succeeded(const std::string& address);
  // Clients without a token, with credentials (cfg.anonymous_share): why
  // connection `id` may not join them (empty: it joined them).
  std::string admit_anonymous(std::uint64_t id);
  std::size_t anonymous_connections() const { return anonymous_.size(); }
  static constexpr std::uint32_t kFreeAuthFailures = 5;
  static constexpr Clock::duration kFirstAuthWait = std::chrono::milliseconds(250);
  static constexpr Clock::duration kLongestAuthWait = std::chrono::seconds(30);
  static constexpr Clock::duration kAuthForgetAfter = std::chrono::seconds(60);
  static constexpr std::size_t kMaxAuthAddresses = 4096;

  // --- The send budget (docs/protocol.md, "Admission") --------------------
  // The budget is in frames/s of own TCP streams (a forward-kinematics run,
  // an encoding and a TCP send each). Another kind of frame costs a share of
  // one, measured on the reference machine (issue 39's grids, CPU per
  // delivered frame at 1,000-10,000 subscribers, and what each kind sends at
  // saturation): an own stream's frame over UDP about 0.7 of it, a frame of
  // a shared stream someone else's tick computed 0.85 over TCP and 0.55 over
  // UDP (the send alone; 0.81-0.93 and 0.42-0.59 in two grids), and a
  // multicast subscriber's share of its stream's one send nearly nothing
  // (its control connection's bookkeeping).
  enum class SendKind { kOwnTcp, kOwnUdp, kSharedTcp, kSharedUdp, kMulticast };
  static double send_cost(SendKind kind);
  // `rate_hz` frames/s of `kind`, in millihertz of the budget's unit.
  static std::uint64_t cost_mhz(double rate_hz, SendKind kind);
  // Commits `cost_mhz` (cost_mhz() of the subscription's `rate_hz`), or says
  // why the budget refuses it (counted). A live source commits its declared
  // rate as own frames (every frame it takes is computed for its views,
  // whoever watches), which RateHold holds it to.
  enum class Asker { kSubscription, kPublication };
  std::optional<std::string> commit_rate(double rate_hz, std::uint64_t cost_mhz, Asker asker = Asker::kSubscription);
  void release_rate(std::uint64_t rate_mhz) { committed_mhz_ -= rate_mhz; }
  double committed_frames_per_second() const { return static_cast<double>(committed_mhz_) / 1000.0; }
  std::uint64_t committed_mhz() const { return committed_mhz_; }
  std::uint64_t subscriptions_refused() const { return subscriptions_refused_; }
  std::uint64_t publications_refused() const { return publications_refused_; }

  // --- View bytes: motion bytes views own (edited copies) -----------------
  std::uint64_t view_bytes() const { return view_bytes_; }
  void set_view_bytes(std::uint64_t bytes) { view_bytes_ = bytes; }
  void release_view_bytes(std::uint64_t bytes) { view_bytes_ -= bytes; }

 private:
  const ServerConfig& cfg_;
  std::uint64_t next_id_ = 1;
  std::map<std::uint64_t, Entry> connections_;
  std::map<std::string, std::size_t> per_address_;  // open connections by IP address
  // Connections waiting for their Hello, by id: ids grow, so the first is
  // the oldest (admit() pushes it out past max_pending_handshakes).
  std::map<std::uint64_t, std::weak_ptr<Outbox>> pending_hello_;
  // Connections accepted, by transport, and the counters of those closed,
  // for lifetime totals.
  std::map<std::string, std::uint64_t, std::less<>> accepted_;
  std::map<std::string, ConnectionCounters, std::less<>> closed_counters_;
  std::uint64_t connections_refused_ = 0;
  LogLimiter refusal_log_{5, std::chrono::seconds(10)};
  std::uint64_t hellos_refused_ = 0;
  LogLimiter hello_log_{5, std::chrono::seconds(10)};
  struct AuthFailures {
    std::uint32_t failures = 0;
    Clock::time_point until{};  // no Hello is checked before
  };
  std::map<std::string, AuthFailures> auth_failures_;  // by address_group, at most kMaxAuthAddresses
  std::set<std::uint64_t> anonymous_;                  // connections in without a token (with credentials)
  // Frames per second the subscriptions ask for, in millihertz (integers:
  // no drift however many come and go), against cfg.send_budget.
  std::uint64_t committed_mhz_ = 0;
  std::uint64_t subscriptions_refused_ = 0;
  std::uint64_t publications_refused_ = 0;
  std::uint64_t view_bytes_ = 0;
};

}  // namespace gmr::server
