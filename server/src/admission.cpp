#include "admission.h"

#include <cmath>

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>

namespace gmr::server {

Admission::Admission(const ServerConfig& cfg)
    : buffers(cfg.max_buffered_bytes, cfg.max_buffered_bytes / std::max<std::size_t>(1, cfg.max_connections)),
      cfg_(cfg) {}

std::string Admission::admit(const std::string& address) {
  if (cfg_.max_connections_per_address != 0) {
    auto it = per_address_.find(address_group(address));
    if (it != per_address_.end() && it->second >= cfg_.max_connections_per_address) {
      return "the server's limit of " + std::to_string(cfg_.max_connections_per_address) +
             " connections from one address (--max-connections-per-address)";
    }
  }
  // Connections still waiting for their Hello: past the cap, the oldest of
  // them gives way (it had its chance; a real client says Hello at once).
  while (!pending_hello_.empty() && pending_hello_.size() >= cfg_.max_pending_handshakes) {
    const std::weak_ptr<Outbox> oldest = pending_hello_.begin()->second;
    pending_hello_.erase(pending_hello_.begin());  // before stop(), whose remove() erases by id
    if (auto c = oldest.lock(); c && !c->stopped()) c->stop("made room for a new connection: no Hello yet");
  }
  if (connections_.size() >= cfg_.max_connections) {
    return "the server's limit of " + std::to_string(cfg_.max_connections) + " connections (--max-connections)";
  }
  return {};
}

void Admission::refused(const std::string& why, bool log) {
  ++connections_refused_;
  if (std::uint64_t suppressed = 0; log && refusal_log_.allow(suppressed)) {
    spdlog::warn("refusing a connection: {}{}", why,
                 suppressed ? " (" + std::to_string(suppressed) + " more refusals not logged)" : std::string());
  }
}

Admission::Entry& Admission::add(const std::shared_ptr<Outbox>& connection, std::weak_ptr<SessionInfo> session,
                                 const std::string& address) {
  auto& entry = connections_[connection->id()];
  entry = Entry{connection, std::move(session), address};
  pending_hello_[connection->id()] = connection;
  ++per_address_[address_group(address)];
  ++accepted_[connection->transport()];
  return entry;
}

std::optional<Admission::Entry> Admission::remove(std::uint64_t id) {
  auto it = connections_.find(id);
  if (it == connections_.end()) return std::nullopt;
  Entry entry = std::move(it->second);
  if (auto c = entry.connection.lock()) closed_counters_[c->transport()].add_totals(c->counters());
  if (auto n = per_address_.find(address_group(entry.address)); n != per_address_.end() && --n->second == 0) {
    per_address_.erase(n);
  }
  connections_.erase(it);
  pending_hello_.erase(id);
  anonymous_.erase(id);
  return entry;
}

std::map<std::string, ConnectionCounters, std::less<>> Admission::totals_by_transport() const {
  auto totals = closed_counters_;
  for (const auto& [id, entry] : connections_) {
    if (auto c = entry.connection.lock()) totals[c->transport()].add_totals(c->counters());
  }
  return totals;
}

ConnectionCounters Admission::totals() const {
  ConnectionCounters all;
  for (const auto& [transport, closed] : closed_counters_) all.add_totals(closed);
  for (const auto& [id, entry] : connections_) {
    if (auto open = entry.connection.lock()) all.add_totals(open->counters());
  }
  return all;
}

Admission::Holdings Admission::holdings() const {
  Holdings h;
  for (const auto& [id, entry] : connections_) {
    auto c = entry.connection.lock();
    if (!c) continue;
    const std::string transport = c->transport();
    ++h.connections[transport];
    if (auto session = entry.session.lock()) {
      h.views += session->view_count();
      const auto [stream_subs, udp_subs] = session->subscription_count();
      h.subscriptions[transport] += stream_subs;
      h.subscriptions["udp"] += udp_subs;
    }
  }
  return h;
}

std::vector<SessionStats> Admission::session_stats() const {
  std::vector<SessionStats> out;
  for (const auto& [id, entry] : connections_) {
    auto c = entry.connection.lock();
    if (!c) continue;
    const ConnectionCounters k = c->counters();
    SessionStats s;
    s.id = id;
    s.frames_sent = k.frames_sent;
    s.frames_dropped = k.frames_dropped;
    s.frames_skipped = k.frames_skipped;
    s.queued_bytes = k.queued_bytes;
    s.max_queued_bytes = k.max_queued_bytes;
    s.io_thread = entry.lane;
    auto session = entry.session.lock();
    s.udp_registered = session && session->has_udp_endpoint();
    out.push_back(s);
  }
  return out;
}

std::vector<double> Admission::frame_wait_p99s() const {
  std::vector<double> out;
  for (const auto& [id, entry] : connections_) {
    auto c = entry.connection.lock();
    if (!c) continue;
    const WaitHistogram wait = c->counters().frame_wait;
    if (wait.count() != 0) out.push_back(wait.quantile_seconds(0.99));
  }
  std::sort(out.begin(), out.end());
  return out;
}

bool Admission::hello_refused(std::uint64_t& suppressed) {
  ++hellos_refused_;
  return hello_log_.allow(suppressed);
}

std::optional<Clock::duration> Admission::auth_wait(const std::string& address) const {
  auto it = auth_failures_.find(address_group(address));
  if (it == auth_failures_.end()) return std::nullopt;
  const auto now = Clock::now();
  if (it->second.until <= now) return std::nullopt;
  return it->second.until - now;
}

void Admission::auth_failed(const std::string& address) {
  const auto now = Clock::now();
  const std::string group = address_group(address);
  if (auth_failures_.size() >= kMaxAuthAddresses && !auth_failures_.contains(group)) {
    // Forget the addresses whose wait is over (a long quiet one starts
    // afresh); should all still wait, the one waiting least.
    std::erase_if(auth_failures_, [&](const auto& e) { return e.second.until + kAuthForgetAfter <= now; });
    if (auth_failures_.size() >= kMaxAuthAddresses) {
      auto least = std::min_element(auth_failures_.begin(), auth_failures_.end(),
                                    [](const auto& a, const auto& b) { return a.second.until < b.second.until; });
      auth_failures_.erase(least);
    }
  }
  AuthFailures& f = auth_failures_[group];
  if (f.until + kAuthForgetAfter <= now) f.failures = 0;  // quiet for long: a fresh start
  ++f.failures;
  if (f.failures > kFreeAuthFailures) {
    const auto doublings = std::min<std::uint32_t>(f.failures - kFreeAuthFailures - 1, 10);
    const auto wait = std::min<Clock::duration>(kFirstAuthWait * (1 << doublings), kLongestAuthWait);
    f.until = now + wait;
  } else {
    f.until = now;
  }
}

void Admission::auth_succeeded(const std::string& address) { auth_failures_.erase(address_group(address)); }

std::string Admission::admit_anonymous(std::uint64_t id) {
  const auto share = static_cast<std::size_t>(static_cast<double>(cfg_.max_connections) * cfg_.anonymous_share);
  if (cfg_.anonymous_share < 1.0 && anonymous_.size() >= std::max<std::size_t>(1, share)) {
    return "clients without a token hold " + std::to_string(anonymous_.size()) + " of the " +
           std::to_string(cfg_.max_connections) + " connections, their share (--anonymous-share " +
           std::to_string(cfg_.anonymous_share).substr(0, 4) + "): connect with a token, or later";
  }
  anonymous_.insert(id);
  return {};
}

double Admission::send_cost(SendKind kind) {
  switch (kind) {
    case SendKind::kOwnTcp:
      return 1.0;
    case SendKind::kOwnUdp:
      return 0.7;
    case SendKind::kSharedTcp:
      return 0.85;
    case SendKind::kSharedUdp:
      return 0.55;
    case SendKind::kMulticast:
      return 0.005;
  }
  return 1.0;
}

std::uint64_t Admission::cost_mhz(double rate_hz, SendKind kind) {
  return static_cast<std::uint64_t>(std::llround(rate_hz * send_cost(kind) * 1000.0));
}

std::optional<std::string> Admission::commit_rate(double rate_hz, std::uint64_t cost_mhz, Asker asker) {
  if (cfg_.send_budget > 0 && static_cast<double>(committed_mhz_ + cost_mhz) > cfg_.send_budget * 1000.0) {
    ++(asker == Asker::kSubscription ? subscriptions_refused_ : publications_refused_);
    char text[400];
    std::snprintf(text, sizeof text,
                  "the server's subscriptions already ask for %.0f of the %.0f frames/s it can send "
                  "(--send-budget, in own-stream TCP frames; live sources count their declared rate); "
                  "%.1f Hz more (%.1f of them) would pass it: %s",
                  static_cast<double>(committed_mhz_) / 1000.0, cfg_.send_budget, rate_hz,
                  static_cast<double>(cost_mhz) / 1000.0,
                  asker == Asker::kSubscription ? "subscribe at a lower rate, or connect to another replica"
                                                : "publish at a lower rate, or to another replica");
    return std::string(text);
  }
  committed_mhz_ += cost_mhz;
  return std::nullopt;
}

}  // namespace gmr::server
