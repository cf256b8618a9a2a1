// Several gmr-server replicas share their live sources through NATS
// (relay.h; docs/deployment.md). A source published on
// one replica is announced on the subject, its frames follow, and every
// other replica serves it as a live source of its own list, to its own
// clients, through their own views. Announces repeat every second: a
// replica started later learns of running sources, and a source whose
// replica stopped talking (killed) ends after cfg.relay_timeout.
#include <spdlog/spdlog.h>

#include <cmath>
#include <random>

#include "gmr/wire/convert.h"
#include "server_state.h"

namespace gmr::server {

namespace {

std::string random_origin() {
  std::random_device rd;
  const std::uint64_t v = (static_cast<std::uint64_t>(rd()) << 32) ^ rd();
  char text[17];
  std::snprintf(text, sizeof text, "%016llx", static_cast<unsigned long long>(v));
  return text;
}

std::string key_of(const std::string& origin, std::uint64_t serial) { return origin + "#" + std::to_string(serial); }

// The tail of a rate-limited log line: how many were left out before it.
std::string suppressed(std::uint64_t n) {
  return n ? " (" + std::to_string(n) + " more such lines not logged)" : std::string();
}

}  // namespace

void Server::Impl::start_relay() {
  if (cfg.nats_url.empty()) return;
  relay = std::make_unique<NatsRelay>(io, cfg.nats_url, cfg.nats_subject, random_origin(),
                                      [this](relay_pb::LiveRelay m) { on_relay(std::move(m)); });
  if (Status s = relay->start(); !s.ok()) throw std::runtime_error(s.error().to_string());
  spdlog::info("replica {}: live sources shared on NATS {} subject {}", relay->origin(), cfg.nats_url,
               cfg.nats_subject);
  relay_timer = std::make_unique<net::steady_timer>(io);
  relay_tick();
}

void Server::Impl::relay_tick() {
  if (stopping) return;
  for (const auto& [name, source] : live) {
    if (source->origin().empty()) relay_announce(*source);
  }
  // Sources whose replica stopped talking.
  const auto now = Clock::now();
  for (auto it = remote_sources.begin(); it != remote_sources.end();) {
    if (now - it->second.heard <= cfg.relay_timeout) {
      ++it;
      continue;
    }
    if (auto& source = it->second.source) {
      spdlog::warn("live {}: nothing from replica {} for {} ms: ended", printable(source->name(), 200),
                   source->origin(), cfg.relay_timeout.count());
      if (auto l = live.find(source->name()); l != live.end() && l->second == source) live.erase(l);
      source->end("the replica publishing the live source went away");
    }
    it = remote_sources.erase(it);
  }
  relay_timer->expires_after(std::chrono::seconds(1));
  relay_timer->async_wait([this](const boost::system::error_code& ec) {
    if (!ec) relay_tick();
  });
}

void Server::Impl::relay_announce(const LiveSource& source) {
  if (!relay) return;
  relay_pb::LiveRelay m;
  m.set_serial(source.serial());
  auto* a = m.mutable_announce();
  a->set_name(source.name());
  wire::to_proto(source.latest()->skeleton, *a->mutable_skeleton());
  a->set_frame_time(source.frame_time());
  a->set_metres_per_unit(source.metres_per_unit());
  relay->send(std::move(m));
}

void Server::Impl::relay_frame(const LiveSource& source, std::span<const double> values) {
  if (!relay) return;
  relay_pb::LiveRelay m;
  m.set_serial(source.serial());
  m.mutable_frame()->set_index(source.frames() - 1);
  m.mutable_frame()->mutable_values()->Add(values.begin(), values.end());
  relay->send(std::move(m));
}

void Server::Impl::relay_end(const LiveSource& source, const std::string& reason) {
  if (!relay) return;
  relay_pb::LiveRelay m;
  m.set_serial(source.serial());
  m.set_end(reason);
  relay->send(std::move(m));
}

void Server::Impl::on_relay(relay_pb::LiveRelay m) {
  if (stopping) return;
  const std::string key = key_of(m.origin(), m.serial());
  auto it = remote_sources.find(key);
  switch (m.body_case()) {
    case relay_pb::LiveRelay::kAnnounce: {
      if (it != remote_sources.end()) {
        it->second.heard = Clock::now();
        return;
      }
      if (remote_sources.size() >= cfg.max_remote_sources) {
        ++relay_announces_refused;
        if (std::uint64_t more = 0; relay_log_limit.allow(more)) {
          spdlog::warn("replica {}: live {} not served here: {} sources of other replicas are (--max-remote-sources){}",
                       printable(m.origin(), 64), printable(m.announce().name(), 200), remote_sources.size(),
                       suppressed(more));
        }
        return;
      }
      const auto& a = m.announce();
      RemoteSource r{nullptr, Clock::now()};
      auto checked = check_announcement(a, cfg);
      if (const auto* refusal = std::get_if<Refusal>(&checked)) {
        ++relay_announces_refused;
        if (std::uint64_t more = 0; relay_log_limit.allow(more)) {
          spdlog::warn("replica {}: live {} refused: {}{}", printable(m.origin(), 64), printable(a.name(), 200),
                       printable(refusal->message, 300), suppressed(more));
        }
      } else if (by_name.contains(a.name()) || live.contains(a.name())) {
        if (std::uint64_t more = 0; relay_log_limit.allow(more)) {
          spdlog::warn("replica {}: live {} has a name this replica serves already: ignored here{}",
                       printable(m.origin(), 64), printable(a.name(), 200), suppressed(more));
        }
      } else {
        r.source = std::make_shared<LiveSource>(a.name(), next_live_serial++, std::move(std::get<Skeleton>(checked)),
                                                a.frame_time(), a.metres_per_unit());
        r.source->set_origin(m.origin());
        live[a.name()] = r.source;
        spdlog::info("live {}: published on replica {}, served here too", printable(a.name(), 200),
                     printable(m.origin(), 64));
      }
      remote_sources.emplace(key, std::move(r));
      return;
    }
    case relay_pb::LiveRelay::kFrame: {
      if (it == remote_sources.end() || !it->second.source) return;  // announced later, or ignored
      it->second.heard = Clock::now();
      const auto& f = m.frame();
      if (it->second.source->push(std::span<const double>(f.values().data(), static_cast<std::size_t>(f.values_size())),
                                  f.index())
              .ok()) {
        ++live_frames_received;
      } else {
        ++live_frames_refused;
      }
      return;
    }
    case relay_pb::LiveRelay::kEnd: {
      if (it == remote_sources.end()) return;
      if (auto source = it->second.source) {
        if (auto l = live.find(source->name()); l != live.end() && l->second == source) live.erase(l);
        source->end(m.end());
      }
      remote_sources.erase(it);
      return;
    }
    default: return;
  }
}

}  // namespace gmr::server
