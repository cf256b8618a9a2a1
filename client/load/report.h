// What gmr-load measured, in a form several processes can merge: counts and
// a latency histogram (not a list of samples, and not percentiles, which do
// not add up), written as JSON and printed as text or a gnuplot PNG.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

namespace gmr::load {

// Latencies in nanoseconds, log-linear: exact below 64 ns, then 32 buckets
// per power of two (each within about 3% of its value), up to about 18
// minutes; larger values land in the last bucket, negative ones (clock skew
// between hosts) in the first.
class Histogram {
 public:
  static constexpr int kSubBits = 5;
  static constexpr std::size_t kBuckets = 32 * 36 + 64;

  void add(std::int64_t ns);
  void add(const Histogram& other);
  std::uint64_t count() const { return count_; }
  std::int64_t max() const { return max_; }
  // The value under which a fraction `q` (0..1) of the samples lie: the
  // midpoint of the bucket that holds that rank (the maximum for q = 1).
  double quantile_ns(double q) const;

  static std::size_t bucket_of(std::int64_t ns);
  static std::int64_t bucket_low(std::size_t bucket);   // smallest value in it
  static std::int64_t bucket_high(std::size_t bucket);  // one past the largest
  std::uint64_t at(std::size_t bucket) const { return counts_[bucket]; }
  void set(std::size_t bucket, std::uint64_t n);  // for reading JSON back

 private:
  std::array<std::uint64_t, kBuckets> counts_{};
  std::uint64_t count_ = 0;
  std::int64_t max_ = 0;
};

// A coarse latency histogram, small enough for one per subscriber (420
// bytes): 4 buckets per power of two from 1 us (each within about 19% of
// its value) up to about 70 s; below 1 us, one bucket.
class CoarseHistogram {
 public:
  static constexpr std::size_t kBuckets = 1 + 4 * 26;
  void add(std::int64_t ns);
  std::uint32_t count() const { return count_; }
  // The upper edge of the bucket that holds rank q (0..1) of the samples.
  double quantile_ns(double q) const;

 private:
  std::array<std::uint32_t, kBuckets> counts_{};
  std::uint32_t count_ = 0;
};

// One gmr-load run, or several merged.
struct LoadResult {
  int processes = 1;
  std::uint64_t clients = 0;
  std::string motion;
  std::string transport = "tcp";  // "tcp", "udp" or "multicast" (frames to the server's group)
  bool shared = false;
  double rate_hz = 0;  // per client
  double seconds = 0;  // the measured window
  double setup_seconds = 0;
  std::uint64_t frames = 0;  // received in the window
  std::uint64_t gaps = 0;    // sequence numbers that never arrived
  std::uint64_t stale = 0;   // dropped by the clients as older than max staleness
  Histogram latency;         // receive time - Frame.server_send_time_ns (encoding)
  // Frame.server_write_time_ns - server_send_time_ns, of the frames that
  // carry a write stamp: how long a frame waited in the server after its
  // encoding (behind the fan-out to other subscribers and the lane's queue).
  Histogram server_wait;
  // One sample per subscriber: its own p99 latency, and its own p99 wait in
  // the server (the tail each subscriber sees, where the histograms above mix
  // all subscribers' frames: a subscriber always last in a fan-out shows here).
  Histogram subscriber_p99_latency;
  Histogram subscriber_p99_server_wait;
  // Of this process (merged: summed).
  double cpu_user_seconds = 0;
  double cpu_system_seconds = 0;
  unsigned threads = 0;
  // The server's counters over the window, all its clients' (gmr-load
  // measures a server of its own); merged, the largest.
  bool have_server = false;
  std::uint64_t server_sent = 0, server_dropped = 0, server_skipped = 0;
  std::uint64_t server_computed = 0, server_encoded = 0, server_late_total = 0;
  std::uint32_t server_io_threads = 0;      // its I/O threads (0: it did not say)
  std::uint64_t server_multicast_sent = 0;  // frames it sent to its multicast group
  // The server process's CPU over the window, when gmr-load was told its pid.
  double server_cpu_seconds = -1;
};

std::string to_json(const LoadResult& r);
// Throws std::runtime_error naming `label` and what is wrong.
LoadResult from_json(const std::string& text, const std::string& label);
// Runs that measured the same server at the same time, as one.
LoadResult merge(const std::vector<LoadResult>& runs);
// The text report.
std::string describe(const LoadResult& r);
// A PNG of the latency distribution through gnuplot. Returns an error
// message, empty on success.
std::string plot(const LoadResult& r, const std::string& png);

}  // namespace gmr::load
