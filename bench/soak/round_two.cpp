#include "round_two.h"

#include <google/protobuf/util/json_util.h>
#include <sys/stat.h>

#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include "gmr/demo/demo_library.h"
#include "gmr/io/gmr_file.h"
#include "gmr/relay/v1/relay.pb.h"
#include "sockets.h"

namespace gmr::soak {
namespace {

namespace pb = ::gmr::stream::v1;

double now_s() {
  static const auto t0 = std::chrono::steady_clock::now();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Where each attack comes from: one address per attack, as if from another host.
constexpr const char* kHttpSilentFrom = "127.0.0.10";
constexpr const char* kHeartbeatFrom = "127.0.0.11";
constexpr const char* kBodiesFrom = "127.0.0.12";
constexpr const char* kWsBodiesFrom = "127.0.0.13";
constexpr const char* kLogFloodFrom = "127.0.0.14";
constexpr const char* kGuessFrom = "127.0.0.15";
constexpr const char* kJsonFrom = "127.0.0.16";

// The first whole message on `fd` within its timeout (a HelloReply, an Error).
std::optional<pb::ServerMessage> read_message(int fd) {
  std::string bytes;
  char buf[4096];
  while (bytes.size() < 4 || bytes.size() < 4 + wire::read_length_prefix(std::span<const std::uint8_t, 4>(
                                                    reinterpret_cast<const std::uint8_t*>(bytes.data()), 4))) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) return std::nullopt;
    bytes.append(buf, static_cast<std::size_t>(n));
    if (bytes.size() > (1u << 20)) return std::nullopt;
  }
  const auto length = wire::read_length_prefix(
      std::span<const std::uint8_t, 4>(reinterpret_cast<const std::uint8_t*>(bytes.data()), 4));
  pb::ServerMessage m;
  if (!m.ParseFromArray(bytes.data() + 4, static_cast<int>(length))) return std::nullopt;
  return m;
}

// Reads what is waiting (heartbeats the server sent) to see whether it closed.
bool closed_by_peer(int fd) {
  char buf[4096];
  for (;;) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, MSG_DONTWAIT);
    if (n > 0) continue;
    return n == 0 || (errno != EAGAIN && errno != EWOULDBLOCK);
  }
}

std::string json(const pb::ClientMessage& m) {
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(m, &out);
  return out;
}

// A chain of `joints` with rotations (the root also positions): a live
// source whose frames are `channel_count` values.
Skeleton chain_skeleton(int joints, const std::string& joint_prefix = "j") {
  std::vector<Joint> chain;
  for (int j = 0; j < joints; ++j) {
    Joint k;
    k.name = joint_prefix + std::to_string(j);
    k.parent = j - 1;
    k.offset = Eigen::Vector3d(0, 1, 0);
    if (j == 0) k.channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
    k.channels.insert(k.channels.end(), {ChannelType::kZrotation, ChannelType::kXrotation, ChannelType::kYrotation});
    chain.push_back(std::move(k));
  }
  return Skeleton::create(std::move(chain)).value();
}

}  // namespace

// A publisher recording a 1,024-joint source at 120 Hz for 30 s (about
// 88 MB of values), one at a time: past --max-record-total-bytes it is cut,
// past the directory's bound new ones are refused.
struct RoundTwo::Recorder {
  std::unique_ptr<client::Client> client;
  std::uint32_t publication = 0;
  std::vector<double> values;
  double started = 0, until = 0;
  std::uint64_t frames = 0;
};

Result<std::unique_ptr<client::Client>> RoundTwo::connect(const std::string& token, const char* name) const {
  client::ClientOptions o;
  o.host = s_.host;
  o.port = s_.port;
  o.auth_token = token;
  o.client_name = name;
  return client::Client::connect(o);
}

RoundTwo::RoundTwo(RoundTwoSettings settings) : s_(std::move(settings)) {}

RoundTwo::~RoundTwo() { tick(true); }

void RoundTwo::count(const char* attack, const std::string& outcome, std::uint64_t n) {
  tallies_[attack].outcomes[outcome] += n;
}

RoundTwo::Held& RoundTwo::hold(int fd, double seconds, const char* attack) {
  Held& h = held_.emplace_back();
  h.fd = fd;
  h.opened = now_s();
  h.until = h.opened + seconds;
  h.attack = attack;
  return h;
}

const char* RoundTwo::act(std::mt19937_64& rng) {
  using Attack = void (RoundTwo::*)(std::mt19937_64&);
  static constexpr std::pair<const char*, Attack> kAttacks[] = {
      {"http silent sockets", &RoundTwo::http_silent},
      {"anonymous heartbeaters", &RoundTwo::anonymous_heartbeaters},
      {"tcp bodies in flight", &RoundTwo::tcp_bodies_in_flight},
      {"websocket bodies in flight", &RoundTwo::websocket_bodies_in_flight},
      {"exploding edit", &RoundTwo::exploding_edit},
      {"recording", &RoundTwo::recording},
      {"rogue relay", &RoundTwo::rogue_relay},
      {"live over rate, bad names", &RoundTwo::over_rate_and_bad_names},
      {"log flood", &RoundTwo::log_flood},
      {"token guessing", &RoundTwo::token_guessing},
      {"json blocks", &RoundTwo::json_blocks},
      {"dns rebinding", &RoundTwo::dns_rebinding},
  };
  tick();
  const auto& [name, attack] = kAttacks[turn_++ % std::size(kAttacks)];
  (this->*attack)(rng);
  ++tallies_[name].acts;
  return name;
}

void RoundTwo::tick(bool all) {
  const double now = now_s();
  for (auto it = held_.begin(); it != held_.end();) {
    Held& h = *it;
    if (!h.pending.empty() && h.sent < h.pending.size()) {
      const ssize_t n = ::send(h.fd, h.pending.data() + h.sent, h.pending.size() - h.sent, MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n > 0) h.sent += static_cast<std::size_t>(n);
    }
    if (h.next_heartbeat > 0 && now >= h.next_heartbeat && !all) {
      pb::ClientMessage beat;
      beat.mutable_heartbeat()->set_client_time_ns(1);
      if (h.websocket) {
        send_all(h.fd, ws_frame(2, beat.SerializeAsString()));
      } else {
        send_request(h.fd, 0, beat);
      }
      h.next_heartbeat = now + 5;
    }
    const bool closed = closed_by_peer(h.fd);
    if (closed || all || now >= h.until) {
      count(h.attack, closed ? "closed by the server" : "held to the end");
      count(h.attack, "seconds held", static_cast<std::uint64_t>(now - h.opened + 0.5));
      if (!h.pending.empty()) count(h.attack, "MiB pushed", h.sent >> 20);
      ::close(h.fd);
      it = held_.erase(it);
    } else {
      ++it;
    }
  }
  if (recorder_ && recorder_->client) {
    Recorder& r = *recorder_;
    const auto due = static_cast<std::uint64_t>((std::min(now, r.until) - r.started) * 120.0);
    for (; r.frames < due; ++r.frames) {
      r.values[0] = static_cast<double>(r.frames);
      if (!r.client->publish_frame(r.publication, r.values).ok()) break;
    }
    if (now >= r.until || all) {
      const auto errors = r.client->take_errors();
      count("recording", "frames sent", r.frames);
      if (!errors.empty()) count("recording", "frames refused", errors.size());
      (void)r.client->unpublish(r.publication);
      recorder_.reset();
    }
  }
}

// 20 silent sockets on the HTTP port from one address, held 8 s: past 16 the
// address is refused; the head deadline (5 s) closes the rest.
void RoundTwo::http_silent(std::mt19937_64&) {
  for (int i = 0; i < 20; ++i) {
    const int fd = raw_connect(s_.host, s_.http_port, kHttpSilentFrom);
    if (fd < 0) {
      count("http silent sockets", "connect refused");
      continue;
    }
    hold(fd, 8, "http silent sockets");
  }
}

// 32 connections that say Hello without a token and heartbeat every 5 s,
// meaning to stay 2 minutes: the anonymous share bounds how many are let in,
// the idle timeout closes those holding nothing.
void RoundTwo::anonymous_heartbeaters(std::mt19937_64&) {
  for (int i = 0; i < 32; ++i) {
    const bool ws = i % 4 == 3;
    const int fd = ws ? ws_connect(s_.host, s_.http_port, "gmr.stream.v1", kHeartbeatFrom)
                      : raw_connect(s_.host, s_.port, kHeartbeatFrom);
    if (fd < 0) {
      count("anonymous heartbeaters", "connect refused");
      continue;
    }
    const auto hello = hello_message("soak: heartbeats only");
    if (ws) {
      send_all(fd, ws_frame(2, hello.SerializeAsString()));
      if (drain(fd, 4096) <= 0) {
        count("anonymous heartbeaters", "refused at hello");
        ::close(fd);
        continue;
      }
    } else {
      send_request(fd, 1, hello);
      const auto reply = read_message(fd);
      if (!reply || reply->has_error()) {
        count("anonymous heartbeaters", "refused at hello");
        ::close(fd);
        continue;
      }
    }
    count("anonymous heartbeaters", "admitted");
    Held& h = hold(fd, 120, "anonymous heartbeaters");
    h.next_heartbeat = h.opened + 5;
    h.websocket = ws;
  }
}

// 4 connections, each a 4 MiB message one byte short, pushed as the server
// takes it and held 10 s (TCP after Hello; WebSocket as one binary frame).
void RoundTwo::tcp_bodies_in_flight(std::mt19937_64&) { bodies_in_flight(false); }
void RoundTwo::websocket_bodies_in_flight(std::mt19937_64&) { bodies_in_flight(true); }

void RoundTwo::bodies_in_flight(bool websocket) {
  const char* attack = websocket ? "websocket bodies in flight" : "tcp bodies in flight";
  const std::uint32_t length = wire::kDefaultMaxMessageBytes - 1;
  for (int i = 0; i < 4; ++i) {
    int fd = -1;
    std::string bytes;
    if (websocket) {
      fd = ws_connect(s_.host, s_.http_port, "gmr.stream.v1", kWsBodiesFrom);
      if (fd >= 0) bytes = ws_frame(2, std::string(length - 1, 'x'), length);
    } else {
      fd = raw_connect(s_.host, s_.port, kBodiesFrom);
      if (fd >= 0) {
        send_request(fd, 1, hello_message("soak: body in flight"));
        (void)read_message(fd);
        std::string prefix(4, '\0');
        wire::write_length_prefix(length,
                                  std::span<std::uint8_t, 4>(reinterpret_cast<std::uint8_t*>(prefix.data()), 4));
        bytes = prefix + std::string(length - 1, 'x');
      }
    }
    if (fd < 0) {
      count(attack, "connect refused");
      continue;
    }
    hold(fd, 10, attack).pending = std::move(bytes);
  }
}

// A token holder's SetRoots of all 30 joints of the channel-less 2^20-frame
// chain: refused before it is computed.
void RoundTwo::exploding_edit(std::mt19937_64&) {
  auto c = connect(s_.control_token, "soak: exploding edit");
  if (!c.ok()) return count("exploding edit", "connect failed: " + c.error().to_string());
  auto v = (*c)->create_view(s_.chain_motion);
  if (!v.ok()) return count("exploding edit", "no chain view: " + v.error().to_string());
  std::vector<std::string> roots;
  for (int j = 0; j < 30; ++j) roots.push_back("j" + std::to_string(j));
  const double t0 = now_s();
  auto e = (*c)->set_roots(v->id, roots);
  const double ms = (now_s() - t0) * 1e3;
  if (e.ok()) return count("exploding edit", "accepted");
  count("exploding edit",
        e.error().message.find("RESOURCE_EXHAUSTED") != std::string::npos ? "refused (size)" : "refused otherwise");
  count("exploding edit", ms < 100 ? "answered within 100 ms" : "answered later");
}

void RoundTwo::recording(std::mt19937_64& rng) {
  if (recorder_) return count("recording", "one still running");
  auto c = connect(s_.publish_token, "soak: recording");
  if (!c.ok()) return count("recording", "connect failed");
  const Skeleton skeleton = chain_skeleton(1024);
  client::PublishOptions po;
  po.name = "soak_rec_" + std::to_string(rng() % 1000000);
  po.frame_time = 1.0 / 120;
  po.record = true;
  auto p = (*c)->publish(skeleton, po);
  if (!p.ok()) {
    const std::string why = p.error().message;
    return count("recording", why.find("record") != std::string::npos ? "refused: record budget" : "refused: " + why);
  }
  count("recording", "started");
  auto r = std::make_unique<Recorder>();
  r->client = std::move(c).value();
  r->publication = p->id;
  r->values.assign(static_cast<std::size_t>(skeleton.channel_count()), 0.0);
  r->started = now_s();
  r->until = r->started + 30;
  recorder_ = std::move(r);
}

// A holder of the NATS credentials without the relay secret: announces that
// squat a library name, frames far ahead, ends with escape codes, unsigned,
// with forged MACs, and bytes that are no message at all.
void RoundTwo::rogue_relay(std::mt19937_64& rng) {
  if (s_.nats_port == 0) return count("rogue relay", "skipped: no NATS");
  const int fd = raw_connect(s_.host, s_.nats_port);
  if (fd < 0) return count("rogue relay", "NATS refused the connection");
  (void)drain(fd, 4096);  // INFO
  std::string out = "CONNECT {\"verbose\":false,\"pedantic\":false,\"user\":\"" + s_.nats_user + "\",\"pass\":\"" +
                    s_.nats_password + "\"}\r\n";
  const std::string origin = "rogue-" + std::to_string(rng());
  for (int i = 0; i < 50; ++i) {
    gmr::relay::v1::LiveRelay relay;
    relay.set_origin(origin);
    relay.set_serial(1);
    relay.set_sequence(static_cast<std::uint64_t>(i + 1));
    switch (i % 3) {
      case 0:
        relay.mutable_announce()->set_name("walk");
        break;
      case 1:
        relay.mutable_frame()->set_index(~std::uint64_t{0} - 1);
        relay.mutable_frame()->add_values(666666666);
        break;
      default:
        relay.set_end("\x1b[2Jowned");
        break;
    }
    gmr::relay::v1::SignedRelay signed_relay;
    signed_relay.set_relay(relay.SerializeAsString());
    if (i % 2 == 0) {
      std::string mac(32, '\0');
      for (auto& b : mac) b = static_cast<char>(rng());
      signed_relay.set_mac(mac);
    }
    std::string payload = i % 10 == 9 ? std::string(100, static_cast<char>(rng())) : signed_relay.SerializeAsString();
    out += "PUB " + s_.nats_subject + " " + std::to_string(payload.size()) + "\r\n" + payload + "\r\n";
  }
  out += "PING\r\n";
  send_all(fd, out);
  std::string answer;
  char buf[512];
  while (answer.find("PONG") == std::string::npos && answer.find("-ERR") == std::string::npos) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    answer.append(buf, static_cast<std::size_t>(n));
  }
  count("rogue relay", answer.find("PONG") != std::string::npos ? "50 messages published" : "NATS refused: " + answer);
  ::close(fd);
}

// A publisher that declares 30 Hz and sends 600 frames at once, then tries a
// name with a zero-width space and a joint name with an escape sequence.
void RoundTwo::over_rate_and_bad_names(std::mt19937_64&) {
  const char* attack = "live over rate, bad names";
  auto c = connect(s_.publish_token, "soak: over rate");
  if (!c.ok()) return count(attack, "connect failed");
  client::PublishOptions po;
  po.name = "soak_fast";
  po.frame_time = 1.0 / 30;
  const Skeleton skeleton = chain_skeleton(20);
  auto p = (*c)->publish(skeleton, po);
  if (p.ok()) {
    std::vector<double> values(static_cast<std::size_t>(skeleton.channel_count()), 0.0);
    for (int i = 0; i < 600; ++i) (void)(*c)->publish_frame(p->id, values);
    (void)(*c)->list_motions();  // a round trip: the frames before it were read
    (void)(*c)->unpublish(p->id);
    count(attack, "600 frames sent at 30 Hz declared");
  } else {
    count(attack, "refused: " + p.error().message.substr(0, 60));
  }
  po.name = "walk\u200b";
  count(attack, (*c)->publish(skeleton, po).ok() ? "zero-width name accepted" : "zero-width name refused");
  po.name = "soak_escape";
  count(attack,
        (*c)->publish(chain_skeleton(4, "j\x1b[31m"), po).ok() ? "escape joint accepted" : "escape joint refused");
}

// 100 connections from one address, 4 bytes of garbage each, closed: the
// server's connection log has one budget for all of them.
void RoundTwo::log_flood(std::mt19937_64& rng) {
  for (int i = 0; i < 100; ++i) {
    const int fd = raw_connect(s_.host, s_.port, kLogFloodFrom);
    if (fd < 0) {
      count("log flood", "connect refused");
      continue;
    }
    std::string junk(4, '\0');
    for (auto& ch : junk) ch = static_cast<char>(rng() | 0x80);
    send_all(fd, junk);
    ::close(fd);
  }
  count("log flood", "connections", 100);
}

// 5 Hellos with random 32-character tokens from one address: each failure
// makes the address wait longer before its next try is checked.
void RoundTwo::token_guessing(std::mt19937_64& rng) {
  static const char kAlphabet[] = "abcdefghijklmnopqrstuvwxyz0123456789";
  for (int i = 0; i < 5; ++i) {
    const int fd = raw_connect(s_.host, s_.port, kGuessFrom);
    if (fd < 0) {
      count("token guessing", "connect refused");
      continue;
    }
    std::string token(32, 'a');
    for (auto& ch : token) ch = kAlphabet[rng() % 36];
    send_request(fd, 1, hello_message("soak: guessing", token));
    const auto reply = read_message(fd);
    count("token guessing", !reply ? "no answer within 1 s" : reply->has_error() ? "refused" : "ACCEPTED");
    ::close(fd);
  }
}

// A viewer's token holder on a JSON WebSocket asking the whole of `walk` (240
// frames) with orientations 8 times: replies of 64 KiB or more are converted off the
// control loop.
void RoundTwo::json_blocks(std::mt19937_64&) {
  const int fd = ws_connect(s_.host, s_.http_port, "gmr.stream.v1.json", kJsonFrom);
  if (fd < 0) return count("json blocks", "upgrade refused");
  pb::ClientMessage m = hello_message("soak: json blocks", s_.read_token);
  m.set_request_id(1);
  std::string out = ws_frame(1, json(m));
  m.Clear();
  m.set_request_id(2);
  m.mutable_create_view()->set_motion("walk");
  out += ws_frame(1, json(m));
  for (std::uint64_t id = 3; id < 11; ++id) {
    m.Clear();
    m.set_request_id(id);
    m.mutable_query_frames()->set_view_id(1);
    m.mutable_query_frames()->set_end(240);  // the demo walk's every frame: about 560 KB of JSON
    m.mutable_query_frames()->set_orientations(true);
    out += ws_frame(1, json(m));
  }
  send_all(fd, out);
  std::uint64_t received = 0;
  char buf[65536];
  const double until = now_s() + 2;
  while (now_s() < until) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) break;
    received += static_cast<std::uint64_t>(n);
  }
  count("json blocks", "KiB received", received >> 10);
  ::close(fd);
}

// /metrics and a WebSocket upgrade with the Host a rebinding page would send.
void RoundTwo::dns_rebinding(std::mt19937_64&) {
  const std::string evil = "evil.example:" + std::to_string(s_.http_port);
  count("dns rebinding", "/metrics " + std::to_string(http_status(s_.host, s_.http_port, "/metrics", evil)));
  const int fd = raw_connect(s_.host, s_.http_port);
  if (fd < 0) return count("dns rebinding", "connect refused");
  send_all(fd, "GET /ws HTTP/1.1\r\nHost: " + evil + "\r\nOrigin: http://" + evil +
                   "\r\nConnection: Upgrade\r\nUpgrade: websocket\r\nSec-WebSocket-Version: 13\r\n"
                   "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Protocol: gmr.stream.v1\r\n\r\n");
  char buf[64] = {};
  const ssize_t n = ::recv(fd, buf, sizeof buf - 1, 0);
  count("dns rebinding", "upgrade " + (n >= 12 ? std::string(buf + 9, 3) : std::string("no answer")));
  ::close(fd);
}

bool write_library(const std::string& dir, std::string* error) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::create_directories(dir, ec);
  for (const auto& m : demo_library()) {
    if (auto s = write_gmr(m.motion, fs::path(dir) / (m.name + ".gmr")); !s.ok()) {
      *error = s.error().to_string();
      return false;
    }
  }
  std::ofstream bvh(fs::path(dir) / "chain.bvh");
  bvh << "HIERARCHY\nROOT j0\n{\n  OFFSET 0 0 0\n  CHANNELS 0\n";
  for (int j = 1; j < 30; ++j) bvh << "  JOINT j" << j << "\n  {\n    OFFSET 0 1 0\n    CHANNELS 0\n";
  bvh << "  End Site\n  {\n    OFFSET 0 1 0\n  }\n";
  for (int j = 1; j < 30; ++j) bvh << "  }\n";
  bvh << "}\nMOTION\nFrames: 1048576\nFrame Time: 0.01\n";
  if (!bvh) *error = "cannot write " + (fs::path(dir) / "chain.bvh").string();
  return static_cast<bool>(bvh);
}

}  // namespace gmr::soak
