#include "transport/latency_histogram.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace gmr::server {

LatencyHistogram::LatencyHistogram(const std::vector<double>& bounds)
    : bounds_(bounds), counts_(std::make_unique<std::atomic<std::uint64_t>[]>(bounds.size() + 1)) {
  if (!std::is_sorted(bounds_.begin(), bounds_.end()) ||
      std::adjacent_find(bounds_.begin(), bounds_.end()) != bounds_.end()) {
    throw std::invalid_argument("LatencyHistogram: the bounds must ascend");
  }
  bounds_ns_.reserve(bounds_.size());
  for (double b : bounds_) bounds_ns_.push_back(static_cast<std::int64_t>(std::llround(b * 1e9)));
}

void LatencyHistogram::observe(Clock::duration d) {
  const std::int64_t ns = std::max<std::int64_t>(0, std::chrono::duration_cast<std::chrono::nanoseconds>(d).count());
  // Most waits fall in the first buckets: a short scan beats a binary search.
  std::size_t k = 0;
  while (k < bounds_ns_.size() && ns > bounds_ns_[k]) ++k;
  counts_[k].fetch_add(1, std::memory_order_relaxed);
  sum_ns_.fetch_add(static_cast<std::uint64_t>(ns), std::memory_order_relaxed);
}

prometheus::ClientMetric LatencyHistogram::collect(std::vector<prometheus::ClientMetric::Label> labels) const {
  prometheus::ClientMetric m;
  m.label = std::move(labels);
  std::uint64_t cumulative = 0;
  for (std::size_t k = 0; k <= bounds_.size(); ++k) {
    cumulative += counts_[k].load(std::memory_order_relaxed);
    const double bound = k < bounds_.size() ? bounds_[k] : std::numeric_limits<double>::infinity();
    m.histogram.bucket.push_back(prometheus::ClientMetric::Bucket{cumulative, bound});
  }
  m.histogram.sample_count = cumulative;
  m.histogram.sample_sum = static_cast<double>(sum_ns_.load(std::memory_order_relaxed)) * 1e-9;
  return m;
}

}  // namespace gmr::server
