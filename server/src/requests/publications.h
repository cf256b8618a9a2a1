// Publications: the live sources one session publishes (docs/protocol.md,
// "Live sources"). A connection with a 'publish' role announces a skeleton,
// then pushes frames; its sources end when it says so or when it goes away,
// and a recorded one is written to the record directory then.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>

#include "gmr/server/auth.h"
#include "live/live_source.h"
#include "requests/session_link.h"

namespace gmr::server {

class Publications {
 public:
  explicit Publications(SessionLink& link) : link_(link) {}

  // `role`: the session's (publishing needs kPublish).
  Reply publish(const pb::Publish& r, Role role);
  Reply publish_frame(const pb::PublishFrame& r);
  Reply unpublish(const pb::Unpublish& r);
  // Every source this session publishes ends with `reason`.
  void end_all(const std::string& reason);
  std::size_t count() const { return publications_.size(); }

 private:
  void end(std::uint32_t id, const std::string& reason);

  SessionLink& link_;
  struct Held {
    std::shared_ptr<LiveSource> source;
    std::uint64_t bytes = 0;     // LiveSource::held_bytes, in the memory budget
    std::uint64_t rate_mhz = 0;  // its declared rate, in the send budget
  };
  std::map<std::uint32_t, Held> publications_;
  std::uint32_t next_publication_ = 1;
  LogLimiter over_rate_log_{1, std::chrono::seconds(10)};
};

}  // namespace gmr::server
