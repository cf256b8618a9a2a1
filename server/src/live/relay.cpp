#include "live/relay.h"

#include <nats/nats.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <future>

namespace gmr::server {

// What libnats's threads reach through their closure pointer. It outlives
// every callback: stop() waits for the subscription's completion callback,
// and for the connection's closed callback, which libnats's callback thread
// runs after any other connection callback (disconnected comes first).
struct NatsRelay::Shared {
  net::io_context* io = nullptr;
  std::string origin;
  std::string url;
  Handler handler;
  std::atomic<bool> open{true};
  std::atomic<std::uint64_t>* received = nullptr;
  std::promise<void> completed;
  std::atomic<bool> completed_set{false};
  std::promise<void> closed;
  std::atomic<bool> closed_set{false};
  std::weak_ptr<Shared> self;  // what a posted handler holds
};

namespace {

void on_message(natsConnection*, natsSubscription*, natsMsg* msg, void* closure) {
  auto* s = static_cast<NatsRelay::Shared*>(closure);
  relay_pb::LiveRelay m;
  const bool parsed = m.ParseFromArray(natsMsg_GetData(msg), natsMsg_GetDataLength(msg));
  natsMsg_Destroy(msg);
  if (!parsed) {
    spdlog::warn("nats: a message on the live subject that is not a gmr.relay.v1.LiveRelay: ignored");
    return;
  }
  if (m.origin() == s->origin || !s->open) return;  // our own, or stopping
  ++*s->received;
  net::post(*s->io, [weak = s->self, m = std::move(m)]() mutable {
    auto shared = weak.lock();
    if (shared && shared->open) shared->handler(std::move(m));
  });
}

void on_complete(void* closure) {
  auto* s = static_cast<NatsRelay::Shared*>(closure);
  if (!s->completed_set.exchange(true)) s->completed.set_value();
}

void on_closed(natsConnection*, void* closure) {
  auto* s = static_cast<NatsRelay::Shared*>(closure);
  if (!s->closed_set.exchange(true)) s->closed.set_value();
}

void on_disconnected(natsConnection*, void* closure) {
  const auto* s = static_cast<NatsRelay::Shared*>(closure);
  if (s->open) spdlog::warn("nats: disconnected from {}; live sources of other replicas pause, reconnecting", s->url);
}

void on_reconnected(natsConnection*, void* closure) {
  const auto* s = static_cast<NatsRelay::Shared*>(closure);
  spdlog::info("nats: reconnected to {}", s->url);
}

void on_connected(natsConnection*, void* closure) {
  const auto* s = static_cast<NatsRelay::Shared*>(closure);
  spdlog::info("nats: connected to {}", s->url);
}

}  // namespace

NatsRelay::NatsRelay(net::io_context& io, std::string url, std::string subject, std::string origin, Handler on_message)
    : io_(io), url_(std::move(url)), subject_(std::move(subject)), origin_(std::move(origin)) {
  shared_ = std::make_shared<Shared>();
  shared_->io = &io_;
  shared_->origin = origin_;
  shared_->url = url_;
  shared_->handler = std::move(on_message);
  shared_->received = &received_;
  shared_->self = shared_;
}

NatsRelay::~NatsRelay() { stop(); }

Status NatsRelay::start() {
  natsOptions* opts = nullptr;
  auto fail = [&](const std::string& what, natsStatus s) {
    if (opts != nullptr) natsOptions_Destroy(opts);
    return make_error("nats " + url_ + ": " + what + ": " + natsStatus_GetText(s));
  };
  natsStatus s = natsOptions_Create(&opts);
  if (s != NATS_OK) return fail("options", s);
  if ((s = natsOptions_SetURL(opts, url_.c_str())) != NATS_OK) return fail("URL", s);
  natsOptions_SetName(opts, ("gmr-server " + origin_).c_str());
  natsOptions_SetMaxReconnect(opts, -1);  // forever
  natsOptions_SetReconnectWait(opts, 500);
  natsOptions_SetDisconnectedCB(opts, on_disconnected, shared_.get());
  natsOptions_SetReconnectedCB(opts, on_reconnected, shared_.get());
  natsOptions_SetClosedCB(opts, on_closed, shared_.get());
  natsOptions_SetRetryOnFailedConnect(opts, true, on_connected, shared_.get());
  s = natsConnection_Connect(&connection_, opts);
  natsOptions_Destroy(opts);
  opts = nullptr;
  // NATS_NOT_YET_CONNECTED: the first connection is being retried in the background.
  if (s != NATS_OK && s != NATS_NOT_YET_CONNECTED) return fail("connect", s);
  if (s == NATS_NOT_YET_CONNECTED) spdlog::warn("nats: {} is not there yet; retrying in the background", url_);
  if ((s = natsConnection_Subscribe(&subscription_, connection_, subject_.c_str(), on_message, shared_.get())) !=
      NATS_OK) {
    return fail("subscribe to " + subject_, s);
  }
  natsSubscription_SetOnCompleteCB(subscription_, on_complete, shared_.get());
  return Ok{};
}

void NatsRelay::send(relay_pb::LiveRelay m) {
  if (connection_ == nullptr) return;
  m.set_origin(origin_);
  const std::string bytes = m.SerializeAsString();
  if (natsConnection_Publish(connection_, subject_.c_str(), bytes.data(), static_cast<int>(bytes.size())) == NATS_OK) {
    ++sent_;
  } else {
    ++dropped_;
  }
}

void NatsRelay::stop() {
  if (!shared_ || !shared_->open.exchange(false)) return;
  if (subscription_ != nullptr) {
    auto done = shared_->completed.get_future();
    natsSubscription_Unsubscribe(subscription_);
    // The subscription's last callback has returned once this is set.
    if (done.wait_for(std::chrono::seconds(5)) != std::future_status::ready) {
      spdlog::warn("nats: the subscription did not complete within 5 s");
    }
    natsSubscription_Destroy(subscription_);
    subscription_ = nullptr;
  }
  if (connection_ != nullptr) {
    natsConnection_FlushTimeout(connection_, 500);  // the ends of this replica's sources
    auto closed = shared_->closed.get_future();
    natsConnection_Close(connection_);
    // Its last callback has returned once this is set: shared_ may go.
    if (closed.wait_for(std::chrono::seconds(5)) != std::future_status::ready) {
      spdlog::warn("nats: the connection did not report closed within 5 s");
    }
    natsConnection_Destroy(connection_);
    connection_ = nullptr;
  }
}

}  // namespace gmr::server
