// StreamRegistry: every stream the server runs, and the share keys that let
// subscriptions with the same content and schedule join one running stream
// (one FK and one encoding per tick for all of them). A subscription that
// must change alone (pause, seek, a view edit) is split off onto a copy.
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "streams/stream.h"
#include "streams/stream_clock.h"

namespace gmr::server {

class StreamRegistry {
 public:
  // `tick_grid`: ServerConfig::tick_grid, the clock's.
  StreamRegistry(net::io_context& io, StreamCounters& counters, Clock::duration tick_grid = Clock::duration::zero())
      : clock_(io, tick_grid), counters_(counters) {}

  // The key naming everything that shapes a stream's bytes: the motion, its
  // skeleton version and joint structure, the viewpoint, the joints,
  // precision, orientations and the schedule.
  static std::string share_key(const std::string& motion_name, const ViewContent& content,
                               const Stream::Settings& settings);

  // A running, unpaused stream with `key` that has targets, or null.
  std::shared_ptr<Stream> find_running(const std::string& key);
  // A new stream (not started). A non-empty `key` makes it joinable.
  std::shared_ptr<Stream> create(std::shared_ptr<const ViewContent> content, Stream::Settings settings,
                                 const std::string& key);
  // The stream `target` is on afterwards: `stream` itself when the target is
  // alone on it (then no longer joinable), else a copy that took it over.
  std::shared_ptr<Stream> detach(const std::shared_ptr<Stream>& stream, const Target* target);

  // Stream `id`, while some subscription holds it (null: none).
  std::shared_ptr<Stream> find(std::uint64_t id) const;
  // Streams some subscription still holds.
  std::size_t live();
  // Streams with at least one target.
  std::size_t active();
  // Stops every stream's timer (server shutdown).
  // Ends every stream whose content `why` gives a reason for (its
  // subscribers get SubscriptionEnded with it); returns how many.
  std::size_t end_where(const std::function<std::string(const ViewContent&)>& why);
  void stop_all();
  const StreamClock& clock() const { return clock_; }

 private:
  // Forgets streams no subscription holds any more.
  void prune();

  StreamClock clock_;  // every stream's ticks
  StreamCounters& counters_;
  std::uint64_t next_id_ = 1;
  std::map<std::uint64_t, std::weak_ptr<Stream>> streams_;
  std::map<std::string, std::weak_ptr<Stream>> shared_;
};

}  // namespace gmr::server
