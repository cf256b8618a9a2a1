#include "live/replicas.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <random>

#include "gmr/core/names.h"
#include "gmr/wire/convert.h"
#include "live/announcement.h"

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

Replicas::Replicas(net::io_context& io, const ServerConfig& cfg, LiveDirectory& directory)
    : io_(io), cfg_(cfg), directory_(directory) {}

Replicas::~Replicas() { close(); }

void Replicas::start() {
  if (cfg_.nats_url.empty()) return;
  relay_ = std::make_unique<NatsRelay>(io_,
                                       NatsRelay::Options{.url = cfg_.nats_url,
                                                          .subject = cfg_.nats_subject,
                                                          .origin = random_origin(),
                                                          .credentials_file = cfg_.nats_credentials_file,
                                                          .secret = cfg_.relay_secret},
                                       [this](relay_pb::LiveRelay m) { on_relay(std::move(m)); });
  if (Status s = relay_->start(); !s.ok()) throw std::runtime_error(s.error().to_string());
  spdlog::info("replica {}: live sources shared on NATS {} subject {}{}", relay_->origin(), cfg_.nats_url,
               cfg_.nats_subject, cfg_.nats_credentials_file.empty() ? "" : " with credentials");
  if (cfg_.relay_secret.empty()) {
    spdlog::warn(
        "replica {}: relay messages are not authenticated: whoever may publish on {} can put live sources "
        "here (--relay-secret-file, docs/deployment.md)",
        relay_->origin(), cfg_.nats_subject);
  }
  timer_ = std::make_unique<net::steady_timer>(io_);
  tick();
}

void Replicas::stop() {
  stopped_ = true;
  if (timer_) timer_->cancel();
}

void Replicas::close() {
  if (relay_) relay_->stop();
}

void Replicas::tick() {
  if (stopped_) return;
  for (const auto& source : directory_.local_sources()) announce(*source);
  // Sources whose replica stopped talking.
  const auto now = Clock::now();
  for (auto it = remote_.begin(); it != remote_.end();) {
    if (now - it->second.heard <= cfg_.relay_timeout) {
      ++it;
      continue;
    }
    if (auto& source = it->second.source) {
      spdlog::warn("live {}: nothing from replica {} for {} ms: ended", printable(source->name(), 200),
                   source->origin(), cfg_.relay_timeout.count());
      directory_.remove_live(source);
      source->end("the replica publishing the live source went away");
    }
    it = remote_.erase(it);
  }
  timer_->expires_after(std::chrono::seconds(1));
  timer_->async_wait([this](const boost::system::error_code& ec) {
    if (!ec) tick();
  });
}

void Replicas::announce(const LiveSource& source) {
  if (!relay_) return;
  relay_pb::LiveRelay m;
  m.set_serial(source.serial());
  auto* a = m.mutable_announce();
  a->set_name(source.name());
  wire::to_proto(source.latest()->skeleton, *a->mutable_skeleton());
  a->set_frame_time(source.frame_time());
  a->set_metres_per_unit(source.metres_per_unit());
  relay_->send(std::move(m));
}

void Replicas::frame(const LiveSource& source, std::span<const double> values) {
  if (!relay_) return;
  relay_pb::LiveRelay m;
  m.set_serial(source.serial());
  m.mutable_frame()->set_index(source.frames() - 1);
  m.mutable_frame()->mutable_values()->Add(values.begin(), values.end());
  relay_->send(std::move(m));
}

void Replicas::end(const LiveSource& source, const std::string& reason) {
  if (!relay_) return;
  relay_pb::LiveRelay m;
  m.set_serial(source.serial());
  m.set_end(reason);
  relay_->send(std::move(m));
}

void Replicas::on_relay(relay_pb::LiveRelay m) {
  if (stopped_) return;
  const std::string key = key_of(m.origin(), m.serial());
  auto it = remote_.find(key);
  switch (m.body_case()) {
    case relay_pb::LiveRelay::kAnnounce: {
      if (it != remote_.end()) {
        it->second.heard = Clock::now();
        return;
      }
      if (remote_.size() >= cfg_.max_remote_sources) {
        ++announces_refused_;
        if (std::uint64_t more = 0; log_limit_.allow(more)) {
          spdlog::warn("replica {}: live {} not served here: {} sources of other replicas are (--max-remote-sources){}",
                       printable(m.origin(), 64), printable(m.announce().name(), 200), remote_.size(),
                       suppressed(more));
        }
        return;
      }
      const auto& a = m.announce();
      RemoteSource r{nullptr, Clock::now()};
      auto checked = check_announcement(a, cfg_);
      if (const auto* refusal = std::get_if<Refusal>(&checked)) {
        ++announces_refused_;
        if (std::uint64_t more = 0; log_limit_.allow(more)) {
          spdlog::warn("replica {}: live {} refused: {}{}", printable(m.origin(), 64), printable(a.name(), 200),
                       printable(refusal->message, 300), suppressed(more));
        }
      } else if (directory_.serves(a.name())) {
        if (std::uint64_t more = 0; log_limit_.allow(more)) {
          spdlog::warn("replica {}: live {} has a name this replica serves already: ignored here{}",
                       printable(m.origin(), 64), printable(a.name(), 200), suppressed(more));
        }
      } else {
        r.source =
            directory_.add_live(a.name(), std::move(std::get<Skeleton>(checked)), a.frame_time(), a.metres_per_unit());
        r.source->set_origin(m.origin());
        spdlog::info("live {}: published on replica {}, served here too", printable(a.name(), 200),
                     printable(m.origin(), 64));
      }
      remote_.emplace(key, std::move(r));
      return;
    }
    case relay_pb::LiveRelay::kFrame: {
      if (it == remote_.end() || !it->second.source) return;  // announced later, or ignored
      it->second.heard = Clock::now();
      const auto& f = m.frame();
      auto pushed = it->second.source->push(
          std::span<const double>(f.values().data(), static_cast<std::size_t>(f.values_size())), f.index());
      using Fate = LiveDirectory::FrameFate;
      directory_.count_live_frame(!pushed.ok()                                      ? Fate::kRefused
                                  : pushed.value() == LiveSource::Pushed::kOverRate ? Fate::kOverRate
                                                                                    : Fate::kAccepted);
      return;
    }
    case relay_pb::LiveRelay::kEnd: {
      if (it == remote_.end()) return;
      if (auto source = it->second.source) {
        directory_.remove_live(source);
        // The reason reaches subscribers' screens: the rule names follow.
        source->end(name_problem(m.end(), 200).empty() ? m.end() : "the live source ended on another replica");
      }
      remote_.erase(it);
      return;
    }
    default:
      return;
  }
}

}  // namespace gmr::server
