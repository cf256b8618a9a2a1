// LatencyHistogram: a Prometheus histogram of durations that any thread
// fills without a lock, for what is observed per frame or per tick (a
// connection's write, a stream's tick). prometheus::Histogram takes a mutex
// and adds doubles by compare-and-swap for each observation, shared by every
// I/O thread: a tenth of a shared frame's instructions in the server's
// profile (docs/performance.md, "Per subscriber"). Here a bucket's
// count and the sum (integer nanoseconds) are relaxed atomic additions, and
// /metrics reads them as a ClientMetric; a scrape while others observe may
// see a count and the sum a few observations apart, never a torn value.
#pragma once

#include <prometheus/client_metric.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

#include "transport/net.h"

namespace gmr::server {

class LatencyHistogram {
 public:
  // `bounds`: the buckets' upper bounds (seconds, ascending; "le", as
  // Prometheus means it: a value equal to a bound is in its bucket). A last
  // bucket, +Inf, holds the rest.
  explicit LatencyHistogram(const std::vector<double>& bounds);

  // One duration (a negative one counts as zero).
  void observe(Clock::duration d);

  // The histogram as /metrics reports it: cumulative counts per bound and
  // +Inf, their number and their sum in seconds.
  prometheus::ClientMetric collect(std::vector<prometheus::ClientMetric::Label> labels = {}) const;

 private:
  std::vector<double> bounds_;
  std::vector<std::int64_t> bounds_ns_;                   // the same, in nanoseconds
  std::unique_ptr<std::atomic<std::uint64_t>[]> counts_;  // per bucket, +Inf last
  std::atomic<std::uint64_t> sum_ns_{0};
};

}  // namespace gmr::server
