// The second round of hostile clients (docs/security.md, "Hostile input,
// round two"), for gmr-soak: each act() is one attack of the twelve below,
// from a 127.0.0.x address of its own standing in for another host; tick()
// keeps what is held alive (heartbeats, bodies pushed, a recording fed at
// its rate) and lets it go at its deadline. Every attack counts what came of
// it, so the soak's report says the defences answered, not only that the
// server lived.
#pragma once

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "gmr/client/client.h"

namespace gmr::soak {

struct RoundTwoSettings {
  std::string host = "127.0.0.1";
  std::uint16_t port = 0, http_port = 0;
  std::string control_token, publish_token, read_token;
  // A NATS server the gmr-server relays through, with the credentials a
  // rogue holder of them would have but not the relay secret (port 0: no
  // relay attack).
  std::uint16_t nats_port = 0;
  std::string nats_user, nats_password, nats_subject = "gmr.live";
  std::string chain_motion = "chain";  // the library's channel-less 30-joint chain (write_library)
};

// What one kind of attack did, and what the server answered.
struct Tally {
  std::uint64_t acts = 0;
  std::map<std::string, std::uint64_t> outcomes;  // e.g. "403" -> 40
};

class RoundTwo {
 public:
  explicit RoundTwo(RoundTwoSettings settings);
  ~RoundTwo();
  RoundTwo(const RoundTwo&) = delete;
  RoundTwo& operator=(const RoundTwo&) = delete;

  // One attack, chosen in turn; returns its name. Takes at most a few seconds.
  const char* act(std::mt19937_64& rng);
  // Heartbeats, bodies pushed further, the recording fed; what is past its
  // deadline closed (everything with `all`).
  void tick(bool all = false);
  const std::map<std::string, Tally>& tallies() const { return tallies_; }

 private:
  struct Held {
    int fd = -1;
    double until = 0;  // seconds on the soak's clock
    double opened = 0;
    double next_heartbeat = 0;  // 0: none sent (not a heartbeater)
    bool websocket = false;
    std::string pending;  // bytes still to push (a body in flight)
    std::size_t sent = 0;
    const char* attack = "";
  };
  struct Recorder;

  void count(const char* attack, const std::string& outcome, std::uint64_t n = 1);
  // A gmr client of the server holding `token` (the soak's token holders).
  Result<std::unique_ptr<client::Client>> connect(const std::string& token, const char* name) const;
  Held& hold(int fd, double seconds, const char* attack);
  // The attacks, in turn (round_two.cpp says what each does).
  void http_silent(std::mt19937_64& rng);
  void anonymous_heartbeaters(std::mt19937_64& rng);
  void tcp_bodies_in_flight(std::mt19937_64& rng);
  void websocket_bodies_in_flight(std::mt19937_64& rng);
  void bodies_in_flight(bool websocket);
  void exploding_edit(std::mt19937_64& rng);
  void recording(std::mt19937_64& rng);
  void rogue_relay(std::mt19937_64& rng);
  void over_rate_and_bad_names(std::mt19937_64& rng);
  void log_flood(std::mt19937_64& rng);
  void token_guessing(std::mt19937_64& rng);
  void json_blocks(std::mt19937_64& rng);
  void dns_rebinding(std::mt19937_64& rng);

  RoundTwoSettings s_;
  std::map<std::string, Tally> tallies_;
  std::deque<Held> held_;
  std::unique_ptr<Recorder> recorder_;
  std::size_t turn_ = 0;
};

// Writes the soak's library into `dir`: the built-in demo motions as .gmr
// and `chain.bvh`, a channel-less 30-joint chain of 2^20 frames (875 bytes
// that a 30-root SetRoots would turn into 1.5 GB).
bool write_library(const std::string& dir, std::string* error);

}  // namespace gmr::soak
