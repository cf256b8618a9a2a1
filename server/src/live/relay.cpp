#include "live/relay.h"

#include <nats/nats.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <fstream>
#include <future>
#include <map>
#include <sstream>

#include "gmr/core/names.h"

namespace gmr::server {

// What libnats's threads reach through their closure pointer. It outlives
// every callback: stop() waits for the subscription's completion callback,
// and for the connection's closed callback, which libnats's callback thread
// runs after any other connection callback (disconnected comes first).
struct NatsRelay::Shared {
  net::io_context* io = nullptr;
  std::string origin;
  std::string url;
  std::string secret;     // empty: messages are not authenticated
  std::string nkey_seed;  // "nkey" credentials: signs the server's nonce
  Handler handler;
  std::atomic<bool> open{true};
  std::atomic<std::uint64_t>* received = nullptr;
  // Touched on libnats's delivery thread only (one per subscription).
  std::map<std::string, std::uint64_t> last_sequence;  // by origin
  LogLimiter refusal_log{5, std::chrono::seconds(10)};
  std::atomic<std::uint64_t> refused{0};
  std::atomic<std::size_t> in_flight{0};  // posted to io, not handled yet
  std::promise<void> completed;
  std::atomic<bool> completed_set{false};
  std::promise<void> closed;
  std::atomic<bool> closed_set{false};
  std::weak_ptr<Shared> self;  // what a posted handler holds
};

namespace {

constexpr std::size_t kMacBytes = 32;

std::string mac_of(const std::string& secret, const std::string& bytes) {
  unsigned char out[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  HMAC(EVP_sha256(), secret.data(), static_cast<int>(secret.size()),
       reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), out, &length);
  return std::string(reinterpret_cast<const char*>(out), length);
}

void refuse(NatsRelay::Shared& s, const std::string& why) {
  ++s.refused;
  if (std::uint64_t more = 0; s.refusal_log.allow(more)) {
    spdlog::warn("nats: a message on the live subject refused: {}{}", why,
                 more ? " (" + std::to_string(more) + " more not logged)" : std::string());
  }
}

void on_message(natsConnection*, natsSubscription*, natsMsg* msg, void* closure) {
  auto* s = static_cast<NatsRelay::Shared*>(closure);
  relay_pb::SignedRelay signed_relay;
  const bool framed = signed_relay.ParseFromArray(natsMsg_GetData(msg), natsMsg_GetDataLength(msg));
  natsMsg_Destroy(msg);
  if (!s->open) return;
  if (!framed) return refuse(*s, "not a gmr.relay.v1.SignedRelay");
  if (!s->secret.empty()) {
    const std::string& mac = signed_relay.mac();
    if (mac.size() != kMacBytes) return refuse(*s, "no MAC: the publisher does not hold the relay secret");
    const std::string want = mac_of(s->secret, signed_relay.relay());
    if (CRYPTO_memcmp(want.data(), mac.data(), kMacBytes) != 0) {
      return refuse(*s, "its MAC does not check: the publisher does not hold the relay secret");
    }
  }
  relay_pb::LiveRelay m;
  if (!m.ParseFromString(signed_relay.relay())) return refuse(*s, "not a gmr.relay.v1.LiveRelay");
  if (m.origin() == s->origin) return;  // our own
  if (m.origin().empty() || m.origin().size() > 64 || !name_problem(m.origin(), 64).empty()) {
    return refuse(*s, "origin " + printable(m.origin(), 64) + " is not a replica's id");
  }
  // Each origin's messages move forward: a captured one replayed is refused.
  auto it = s->last_sequence.find(m.origin());
  if (it != s->last_sequence.end() && m.sequence() <= it->second) {
    return refuse(*s, "replica " + printable(m.origin(), 64) + ": message " + std::to_string(m.sequence()) + " after " +
                          std::to_string(it->second));
  }
  if (it == s->last_sequence.end()) {
    if (s->last_sequence.size() >= NatsRelay::kMaxOrigins) s->last_sequence.erase(s->last_sequence.begin());
    it = s->last_sequence.emplace(m.origin(), 0).first;
  }
  it->second = m.sequence();
  if (s->in_flight.load() >= NatsRelay::kMaxMessagesInFlight) {
    return refuse(*s, "the server is behind: " + std::to_string(NatsRelay::kMaxMessagesInFlight) +
                          " relay messages already wait for it");
  }
  ++*s->received;
  ++s->in_flight;
  net::post(*s->io, [weak = s->self, m = std::move(m)]() mutable {
    auto shared = weak.lock();
    if (!shared) return;
    --shared->in_flight;
    if (shared->open) shared->handler(std::move(m));
  });
}

// Signs the NATS server's nonce with the nkey seed ("nkey" credentials).
natsStatus sign_nonce(char** error_text, unsigned char** signature, int* length, const char* nonce, void* closure) {
  const auto* s = static_cast<NatsRelay::Shared*>(closure);
  (void)error_text;
  return nats_Sign(s->nkey_seed.c_str(), nonce, signature, length);
}

void on_complete(void* closure) {
  auto* s = static_cast<NatsRelay::Shared*>(closure);
  if (!s->completed_set.exchange(true)) s->completed.set_value();
}

void on_closed(natsConnection* nc, void* closure) {
  auto* s = static_cast<NatsRelay::Shared*>(closure);
  if (s->open) {
    // Not by stop(): NATS refused this replica (its authorization), for good.
    const char* last = nullptr;
    natsConnection_GetLastError(nc, &last);
    spdlog::error(
        "nats: {} closed the connection{}: live sources are not shared with other replicas (are "
        "--nats-creds right?)",
        s->url, last != nullptr && *last != '\0' ? std::string(": ") + last : std::string());
  }
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

Result<std::string> read_relay_secret(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return make_error("relay secret " + path + ": cannot be read");
  std::string line;
  std::getline(in, line);
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; };
  while (!line.empty() && blank(line.back())) line.pop_back();
  std::size_t first = 0;
  while (first < line.size() && blank(line[first])) ++first;
  line.erase(0, first);
  if (line.size() < kMinRelaySecret) {
    return make_error("relay secret " + path + ": " + std::to_string(line.size()) + " characters; at least " +
                      std::to_string(kMinRelaySecret) + " (e.g. openssl rand -hex 32)");
  }
  return line;
}

std::uint64_t NatsRelay::refused() const { return shared_->refused; }

bool NatsRelay::connected() const {
  return connection_ != nullptr && natsConnection_Status(connection_) == NATS_CONN_STATUS_CONNECTED;
}

NatsRelay::NatsRelay(net::io_context& io, Options options, Handler on_message) : io_(io), options_(std::move(options)) {
  shared_ = std::make_shared<Shared>();
  shared_->io = &io_;
  shared_->origin = options_.origin;
  shared_->url = options_.url;
  shared_->secret = options_.secret;
  shared_->handler = std::move(on_message);
  shared_->received = &received_;
  shared_->self = shared_;
}

NatsRelay::~NatsRelay() { stop(); }

Status NatsRelay::apply_credentials(natsOptions* opts) {
  const std::string& path = options_.credentials_file;
  if (path.empty()) return Ok{};
  std::ifstream in(path, std::ios::binary);
  if (!in) return make_error("NATS credentials " + path + ": cannot be read");
  std::ostringstream text;
  text << in.rdbuf();
  if (text.str().size() > (64u << 10)) return make_error("NATS credentials " + path + ": larger than 64 KiB");
  natsStatus s = NATS_OK;
  if (text.str().find("-----BEGIN NATS USER JWT-----") != std::string::npos) {
    s = natsOptions_SetUserCredentialsFromFiles(opts, path.c_str(), nullptr);  // nsc's .creds: JWT and seed
  } else {
    std::map<std::string, std::string> field;
    std::istringstream lines(text.str());
    std::string line;
    for (int number = 1; std::getline(lines, line); ++number) {
      std::istringstream words(line);
      std::string key, value, extra;
      if (!(words >> key) || key[0] == '#') continue;
      if (!(words >> value) || (words >> extra) || field.contains(key) ||
          (key != "user" && key != "password" && key != "token" && key != "nkey" && key != "seed")) {
        return make_error("NATS credentials " + path + ":" + std::to_string(number) +
                          ": expected one of 'user NAME', 'password PASS', 'token TOKEN', 'nkey PUBLIC', "
                          "'seed SEED', each once");
      }
      field[key] = value;
    }
    if (field.contains("user") && field.contains("password") && field.size() == 2) {
      s = natsOptions_SetUserInfo(opts, field["user"].c_str(), field["password"].c_str());
    } else if (field.contains("token") && field.size() == 1) {
      s = natsOptions_SetToken(opts, field["token"].c_str());
    } else if (field.contains("nkey") && field.contains("seed") && field.size() == 2) {
      shared_->nkey_seed = field["seed"];
      s = natsOptions_SetNKey(opts, field["nkey"].c_str(), sign_nonce, shared_.get());
    } else {
      return make_error("NATS credentials " + path +
                        ": give 'user' and 'password', or 'token', or 'nkey' and 'seed' (docs/deployment.md)");
    }
  }
  if (s != NATS_OK) return make_error("NATS credentials " + path + ": " + natsStatus_GetText(s));
  return Ok{};
}

Status NatsRelay::start() {
  natsOptions* opts = nullptr;
  auto fail = [&](const std::string& what, natsStatus s) {
    if (opts != nullptr) natsOptions_Destroy(opts);
    return make_error("nats " + options_.url + ": " + what + ": " + natsStatus_GetText(s));
  };
  natsStatus s = natsOptions_Create(&opts);
  if (s != NATS_OK) return fail("options", s);
  if ((s = natsOptions_SetURL(opts, options_.url.c_str())) != NATS_OK) return fail("URL", s);
  if (Status c = apply_credentials(opts); !c.ok()) {
    natsOptions_Destroy(opts);
    return c;
  }
  natsOptions_SetName(opts, ("gmr-server " + options_.origin).c_str());
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
  if (s == NATS_NOT_YET_CONNECTED) {
    spdlog::warn("nats: {} is not there yet; retrying in the background", options_.url);
  }
  if ((s = natsConnection_Subscribe(&subscription_, connection_, options_.subject.c_str(), on_message,
                                    shared_.get())) != NATS_OK) {
    // NATS closes a connection it does not authorize (libnats then says
    // only "Connection Closed").
    const char* last = nullptr;
    natsConnection_GetLastError(connection_, &last);
    std::string why = last != nullptr && *last != '\0' ? std::string(": ") + last : std::string();
    if (s == NATS_CONNECTION_CLOSED) {
      why += options_.credentials_file.empty()
                 ? " (NATS closed the connection: does it need credentials? --nats-creds)"
                 : " (NATS closed the connection: are the credentials in " + options_.credentials_file + " right?)";
    }
    return fail("subscribe to " + options_.subject + why, s);
  }
  natsSubscription_SetOnCompleteCB(subscription_, on_complete, shared_.get());
  return Ok{};
}

void NatsRelay::send(relay_pb::LiveRelay m) {
  if (connection_ == nullptr) return;
  m.set_origin(options_.origin);
  m.set_sequence(next_sequence_++);
  relay_pb::SignedRelay out;
  out.set_relay(m.SerializeAsString());
  if (!options_.secret.empty()) out.set_mac(mac_of(options_.secret, out.relay()));
  const std::string bytes = out.SerializeAsString();
  if (natsConnection_Publish(connection_, options_.subject.c_str(), bytes.data(), static_cast<int>(bytes.size())) ==
      NATS_OK) {
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
