// LatencyHistogram: the per-frame and per-tick histograms /metrics reports
// (gmr_frame_wait_seconds, gmr_tick_lateness_seconds), filled without a lock.
#include "transport/latency_histogram.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <thread>
#include <vector>

namespace gmr::test {
namespace {

using std::chrono::microseconds;
using std::chrono::nanoseconds;

// A value equal to a bound is in that bound's bucket ("le"); a nanosecond
// more is in the next; past the last bound, +Inf; a negative one is zero.
TEST(LatencyHistogram, EachValueCountsUpToEveryBoundItIsUnder) {
  server::LatencyHistogram h({1e-5, 1e-3, 0.25});
  h.observe(microseconds(10));                                 // le 1e-5
  h.observe(microseconds(10) + nanoseconds(1));                // le 1e-3
  h.observe(microseconds(1000));                               // le 1e-3
  h.observe(std::chrono::milliseconds(250) + nanoseconds(1));  // +Inf
  h.observe(std::chrono::seconds(-3));                         // 0: le 1e-5
  const auto m = h.collect({{"transport", "tcp"}});
  ASSERT_EQ(m.label.size(), 1u);
  EXPECT_EQ(m.label[0].name, "transport");
  EXPECT_EQ(m.label[0].value, "tcp");
  ASSERT_EQ(m.histogram.bucket.size(), 4u);
  const std::uint64_t cumulative[] = {2, 4, 4, 5};
  const double bounds[] = {1e-5, 1e-3, 0.25, INFINITY};
  for (std::size_t k = 0; k < 4; ++k) {
    EXPECT_EQ(m.histogram.bucket[k].cumulative_count, cumulative[k]) << k;
    EXPECT_EQ(m.histogram.bucket[k].upper_bound, bounds[k]) << k;
  }
  EXPECT_EQ(m.histogram.sample_count, 5u);
  EXPECT_NEAR(m.histogram.sample_sum, 10e-6 + 10.001e-6 + 1e-3 + 0.250000001, 1e-12);
}

// Observed from several threads at once (ThreadSanitizer runs this too):
// every observation counted, the sum exact.
TEST(LatencyHistogram, ThreadsObserveAtOnceAndNothingIsLost) {
  server::LatencyHistogram h({1e-5, 1e-4, 1e-3});
  constexpr int kThreads = 4, kEach = 50000;
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&h, t] {
      for (int i = 0; i < kEach; ++i) h.observe(microseconds(t * 30));  // 0, 30, 60, 90 us
    });
  }
  for (auto& t : threads) t.join();
  const auto m = h.collect();
  EXPECT_EQ(m.histogram.sample_count, std::uint64_t{kThreads} * kEach);
  EXPECT_EQ(m.histogram.bucket[0].cumulative_count, std::uint64_t{kEach});  // the zeros
  EXPECT_EQ(m.histogram.bucket[1].cumulative_count, std::uint64_t{kThreads} * kEach);
  EXPECT_DOUBLE_EQ(m.histogram.sample_sum, (0 + 30 + 60 + 90) * 1e-6 * kEach);
}

TEST(LatencyHistogram, BoundsMustAscend) {
  EXPECT_THROW(server::LatencyHistogram({1e-3, 1e-4}), std::invalid_argument);
  EXPECT_THROW(server::LatencyHistogram({1e-3, 1e-3}), std::invalid_argument);
  EXPECT_NO_THROW(server::LatencyHistogram({}));
}

}  // namespace
}  // namespace gmr::test
