// gmr-load: its histogram and merge, and the built program against a live
// server (the first motion by default, the measured window, --json, --merge,
// --plot).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "net_test_util.h"
#include "report.h"

namespace gmr::test {
namespace {

using load::Histogram;

TEST(LoadHistogram, BucketsTileTheLineAndQuantilesAreWithinABucket) {
  // Consecutive buckets meet, and every value falls in the bucket whose bounds hold it.
  for (std::size_t b = 0; b + 1 < Histogram::kBuckets; ++b) {
    ASSERT_EQ(Histogram::bucket_high(b), Histogram::bucket_low(b + 1)) << b;
    ASSERT_LT(Histogram::bucket_low(b), Histogram::bucket_high(b)) << b;
  }
  std::mt19937_64 rng(7);
  std::lognormal_distribution<double> latency(std::log(300'000.0), 1.0);  // around 0.3 ms
  Histogram h;
  std::vector<std::int64_t> samples;
  for (int i = 0; i < 100'000; ++i) {
    const auto ns = static_cast<std::int64_t>(latency(rng));
    const std::size_t b = Histogram::bucket_of(ns);
    ASSERT_LE(Histogram::bucket_low(b), ns);
    ASSERT_LT(ns, Histogram::bucket_high(b));
    h.add(ns);
    samples.push_back(ns);
  }
  std::sort(samples.begin(), samples.end());
  for (double q : {0.5, 0.9, 0.99, 0.999}) {
    const double exact = static_cast<double>(samples[static_cast<std::size_t>(std::ceil(q * samples.size())) - 1]);
    EXPECT_NEAR(h.quantile_ns(q), exact, exact / 32) << "q " << q;
  }
  EXPECT_EQ(h.quantile_ns(1.0), static_cast<double>(samples.back()));
  EXPECT_EQ(h.count(), samples.size());
  // Clock skew between hosts: negative latencies count, in the first bucket.
  h.add(-5);
  EXPECT_EQ(h.at(0), 1u);
}

// The per-subscriber histogram: 4 buckets per octave from 1 us, so a
// quantile's upper edge is within 25% above the sample it stands for.
TEST(LoadHistogram, ACoarseHistogramsQuantilesAreWithinItsBucket) {
  load::CoarseHistogram h;
  EXPECT_EQ(h.quantile_ns(0.99), 0.0);
  std::vector<std::int64_t> samples;
  for (std::int64_t ns = 1500; ns < 5'000'000'000; ns = ns * 11 / 10) samples.push_back(ns);
  for (auto ns : samples) h.add(ns);
  EXPECT_EQ(h.count(), samples.size());
  for (double q : {0.1, 0.5, 0.9, 0.99, 1.0}) {
    const auto want = static_cast<double>(samples[static_cast<std::size_t>(std::ceil(q * samples.size())) - 1]);
    EXPECT_GE(h.quantile_ns(q), want) << q;
    EXPECT_LE(h.quantile_ns(q), 1.26 * want) << q;
  }
  load::CoarseHistogram small;
  small.add(300);
  EXPECT_EQ(small.quantile_ns(0.5), 1024.0) << "under 1 us: one bucket";
}

TEST(LoadReport, JsonRoundTripsAndMergeAddsRuns) {
  load::LoadResult a;
  a.clients = 10;
  a.motion = "walk";
  a.transport = "udp";
  a.rate_hz = 120;
  a.seconds = 2;
  a.frames = 2400;
  a.gaps = 3;
  a.have_server = true;
  a.server_sent = 2403;
  a.server_encoded = 240;
  for (int i = 0; i < 2400; ++i) a.latency.add(100'000 + i * 100);
  for (int i = 0; i < 10; ++i) a.subscriber_p99_latency.add(300'000 + i * 10'000);
  const load::LoadResult back = load::from_json(load::to_json(a), "a.json");
  EXPECT_EQ(back.subscriber_p99_latency.count(), 10u);
  EXPECT_NEAR(back.subscriber_p99_latency.quantile_ns(0.5), a.subscriber_p99_latency.quantile_ns(0.5), 1.0);
  EXPECT_EQ(back.clients, 10u);
  EXPECT_EQ(back.frames, 2400u);
  EXPECT_EQ(back.transport, "udp");
  EXPECT_EQ(back.latency.count(), 2400u);
  EXPECT_NEAR(back.latency.quantile_ns(0.5), a.latency.quantile_ns(0.5), 1.0);
  load::LoadResult b = a;
  b.clients = 5;
  b.frames = 1200;
  b.server_sent = 1200;
  b.server_encoded = 250;  // the same server's own counter, seen from another process
  const load::LoadResult m = load::merge({a, b});
  EXPECT_EQ(m.processes, 2);
  EXPECT_EQ(m.clients, 15u);
  EXPECT_EQ(m.frames, 3600u);
  EXPECT_EQ(m.server_sent, 2403u);  // the server's, seen from both: the largest
  EXPECT_EQ(m.server_encoded, 250u);
  EXPECT_EQ(m.latency.count(), 4800u);
  EXPECT_EQ(m.subscriber_p99_latency.count(), 20u) << "one sample per subscriber of either run";
  b.shared = true;
  EXPECT_THROW(load::merge({a, b}), std::runtime_error);
  EXPECT_THROW(load::from_json("{\"format\": \"other\"}", "x.json"), std::runtime_error);
  EXPECT_THROW(load::from_json("not json", "x.json"), std::runtime_error);
}

struct ToolRun {
  int status = -1;
  std::string out;
};

ToolRun run_shell(const std::string& command) {
  ToolRun r;
  FILE* p = ::popen(("(" + command + ") 2>&1").c_str(), "r");
  if (p == nullptr) return r;
  std::array<char, 4096> buf{};
  while (std::fgets(buf.data(), buf.size(), p) != nullptr) r.out += buf.data();
  r.status = ::pclose(p);
  return r;
}

ToolRun run(const std::string& args) { return run_shell(std::string(GMR_LOAD_PATH) + " " + args); }

nlohmann::json read_json(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return nlohmann::json::parse(s.str());
}

TEST(LoadTool, MeasuresAWindowWritesJsonMergesAndPlots) {
  server::ServerConfig cfg;
  cfg.max_connections_per_address = 0;
  TestServer server(cfg);
  const auto dir = std::filesystem::temp_directory_path() / ("gmr-load-test-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto json = dir / "run.json", png = dir / "run.png", merged = dir / "merged.json";
  // No --motion: the first in the server's list.
  const ToolRun r =
      run("--port " + std::to_string(server.port()) + " --clients 20 --rate 50 --seconds 1 --warmup 0.3 " +
          "--udp --server-pid " + std::to_string(::getpid()) + " --json " + json.string() + " --plot " + png.string());
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("p99.9"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("histogram"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("gmr-load CPU"), std::string::npos) << r.out;
  const auto j = read_json(json);
  EXPECT_EQ(j["motion"], server::builtin_library().front().name);
  EXPECT_EQ(j["clients"], 20);
  EXPECT_EQ(j["transport"], "udp");
  const double seconds = j["seconds"];
  const std::uint64_t frames = j["frames"];
  // 20 clients at 50 Hz for about a second: most frames arrive.
  EXPECT_GE(static_cast<double>(frames), 0.5 * 20 * 50 * seconds) << r.out;
  EXPECT_LE(static_cast<double>(frames), 1.2 * 20 * 50 * seconds) << r.out;
  // The server's counters cover the window (plus the few milliseconds of
  // the snapshots), not the set-up and warm-up before it.
  const std::uint64_t sent = j["server"]["frames_sent"];
  EXPECT_GE(sent + 20, frames);  // a frame in flight as the window opened
  EXPECT_LE(static_cast<double>(sent), static_cast<double>(frames) + 20 * 50 * 0.25) << r.out;
  std::uint64_t histogram = 0;
  for (const auto& b : j["latency_ns"]["buckets"]) histogram += b[1].get<std::uint64_t>();
  EXPECT_EQ(histogram, frames);
  // Every UDP frame carries its write stamp: how long it waited in the
  // server, which is never more than its whole latency.
  std::uint64_t waits = 0;
  for (const auto& b : j["server_wait_ns"]["buckets"]) waits += b[1].get<std::uint64_t>();
  EXPECT_EQ(waits, frames);
  EXPECT_LE(j["server_wait_ns"]["max"].get<std::int64_t>(), j["latency_ns"]["max"].get<std::int64_t>());
  EXPECT_NE(r.out.find("in the server"), std::string::npos) << r.out;
  // Each subscriber's own p99, one sample per subscriber that got frames.
  std::uint64_t subscribers = 0;
  for (const auto& b : j["subscriber_p99_server_wait_ns"]["buckets"]) subscribers += b[1].get<std::uint64_t>();
  EXPECT_EQ(subscribers, 20u);
  EXPECT_NE(r.out.find("p99 latency of each subscriber: median"), std::string::npos) << r.out;
  EXPECT_GE(j["server_cpu_seconds"].get<double>(), 0.0);
  // Two processes' results, merged.
  const ToolRun m = run("--merge " + json.string() + " " + json.string() + " --json " + merged.string());
  ASSERT_EQ(m.status, 0) << m.out;
  EXPECT_NE(m.out.find("40 clients in 2 processes"), std::string::npos) << m.out;
  const auto mj = read_json(merged);
  EXPECT_EQ(mj["frames"].get<std::uint64_t>(), 2 * frames);
  EXPECT_EQ(mj["processes"], 2);
  std::uint64_t merged_waits = 0;
  for (const auto& b : mj["server_wait_ns"]["buckets"]) merged_waits += b[1].get<std::uint64_t>();
  EXPECT_EQ(merged_waits, 2 * frames);
  // The plot is a PNG (gnuplot is one of install-deps' packages).
  std::ifstream in(png, std::ios::binary);
  std::array<char, 8> magic{};
  in.read(magic.data(), magic.size());
  EXPECT_EQ(std::string(magic.data() + 1, 3), "PNG") << "no PNG at " << png;
  // A missing server is one clear line and a failure.
  const ToolRun bad = run("--port 1 --clients 1 --seconds 1");
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.out.find("gmr-load: client 0"), std::string::npos) << bad.out;
  // More clients than the open-files limit allows (two descriptors each) are
  // refused before any connects, saying what to do; under the hard limit,
  // the soft one is raised (here 200 clients need 464 of at most 500).
  const ToolRun too_many = run_shell("ulimit -n 300 && " + std::string(GMR_LOAD_PATH) + " --port " +
                                     std::to_string(server.port()) + " --clients 200 --seconds 1");
  EXPECT_NE(too_many.status, 0);
  EXPECT_NE(too_many.out.find("gmr-load: 200 clients need about 464 open files (a TCP and a UDP socket each) and "
                              "this process may open at most 300"),
            std::string::npos)
      << too_many.out;
  EXPECT_NE(too_many.out.find("--merge"), std::string::npos) << too_many.out;
  const ToolRun fits = run_shell("ulimit -S -n 100 && ulimit -H -n 500 && " + std::string(GMR_LOAD_PATH) + " --port " +
                                 std::to_string(server.port()) + " --clients 200 --rate 20 --seconds 0.5 --warmup 0.2");
  EXPECT_EQ(fits.status, 0) << fits.out;
  EXPECT_NE(fits.out.find("200 clients"), std::string::npos) << fits.out;
  // A server that never answers: each client waits --timeout-ms, then says so.
  ToolRun mute;
  {
    const SilentListener silent;
    ASSERT_NE(silent.port(), 0);
    mute = run("--port " + std::to_string(silent.port()) + " --clients 1 --timeout-ms 300");
  }
  EXPECT_NE(mute.status, 0);
  EXPECT_NE(mute.out.find("within 300 ms"), std::string::npos) << mute.out;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace gmr::test
