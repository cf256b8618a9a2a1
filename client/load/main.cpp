// gmr-load: N clients subscribe to a gmr-server and measure what arrives.
//
//   gmr-load [--host H] [--port P] [--token T] [--tls-ca CA] [--clients N] [--motion M] [--seconds S]
//            [--rate HZ] [--udp] [--shared] [--orientations] [--float64] [--threads T]
//
// The clients share T I/O threads (gmr::client::EventLoop), not one each.
//
// Prints latency (server send time -> client receive time, both system_clock
// on the same machine, so only meaningful on one host or with synced clocks)
// p50/p99/max, frames and drops per second (sequence gaps seen by clients and
// frames the server dropped for slow clients), and the drop policy in effect.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "connect_options.h"
#include "gmr/client/client.h"

namespace {

struct ClientRun {
  std::unique_ptr<gmr::client::Client> client;
  std::uint32_t subscription = 0;
  std::mutex mutex;
  std::vector<std::int64_t> latencies_ns;
  std::uint64_t frames = 0;
  std::uint64_t gaps = 0;
  std::uint64_t last_sequence = 0;
  bool measuring = false;
};

double percentile(std::vector<std::int64_t>& v, double p) {
  if (v.empty()) return 0.0;
  const std::size_t k = std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size() - 1) + 0.5));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return static_cast<double>(v[k]) / 1e6;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"gmr-load: load-test a gmr-server with N streaming clients"};
  gmr::client::ClientOptions connect_options;
  int clients = 10;
  std::string motion = "walk";
  double seconds = 5.0;
  double warmup = 0.5;
  double rate = 0.0;
  bool udp = false, shared = false, orientations = false, float64 = false;
  gmr::cli::add_connect_options(app, connect_options);
  app.add_option("--clients", clients, "Connections, one subscription each")->capture_default_str()->check(CLI::Range(1, 10000));
  app.add_option("--motion", motion, "Motion to stream (looped)")->capture_default_str();
  app.add_option("--seconds", seconds, "Measurement time")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--warmup", warmup, "Seconds ignored after subscribing")->capture_default_str();
  app.add_option("--rate", rate, "Output rate in Hz (0: the motion's rate)")->capture_default_str();
  app.add_flag("--udp", udp, "Frames over UDP");
  app.add_flag("--shared", shared, "All clients join one shared stream (one FK and encoding per tick)");
  app.add_flag("--orientations", orientations, "Send orientations too");
  app.add_flag("--float64", float64, "Send float64 numbers");
  unsigned threads = 2;
  app.add_option("--threads", threads, "I/O threads all the clients share (0: one per client, as before)")
      ->capture_default_str();
  int max_staleness_ms = 0;
  app.add_option("--max-staleness-ms", max_staleness_ms,
                 "Each subscription's staleness bound: older frames are dropped by the server and the clients, and "
                 "counted (0: none, so every frame's latency is measured)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  CLI11_PARSE(app, argc, argv);

  std::vector<std::unique_ptr<ClientRun>> runs;
  gmr::client::SubscribeOptions so;
  so.loop = true;
  so.rate_hz = rate;
  so.udp = udp;
  so.shared = shared;
  so.orientations = orientations;
  so.float64 = float64;
  so.max_staleness = std::chrono::milliseconds(max_staleness_ms);
  double rate_in_effect = 0.0;
  if (threads > 0) connect_options.loop = std::make_shared<gmr::client::EventLoop>(threads);
  const auto setup_started = std::chrono::steady_clock::now();
  for (int i = 0; i < clients; ++i) {
    auto run = std::make_unique<ClientRun>();
    gmr::client::ClientOptions co = connect_options;
    co.client_name = "gmr-load " + std::to_string(i);
    auto c = gmr::client::Client::connect(co);
    if (!c.ok()) {
      std::fprintf(stderr, "gmr-load: client %d: %s\n", i, c.error().to_string().c_str());
      return 1;
    }
    run->client = std::move(c).value();
    auto view = run->client->create_view(motion);
    if (!view.ok()) {
      std::fprintf(stderr, "gmr-load: %s\n", view.error().to_string().c_str());
      return 1;
    }
    ClientRun* r = run.get();
    auto sub = run->client->subscribe(view->id, so, [r](const gmr::client::ReceivedFrame& f) {
      std::lock_guard lock(r->mutex);
      if (!r->measuring) {
        r->last_sequence = f.sequence;
        return;
      }
      if (r->frames > 0 && f.sequence > r->last_sequence + 1) r->gaps += f.sequence - r->last_sequence - 1;
      r->last_sequence = f.sequence;
      ++r->frames;
      r->latencies_ns.push_back(f.receive_time_ns - f.server_send_time_ns);
    });
    if (!sub.ok()) {
      // The server's admission control: measure the clients it took.
      if (!runs.empty() && sub.error().message.find("RESOURCE_EXHAUSTED") != std::string::npos) {
        std::printf("gmr-load: the server admitted %zu of %d subscriptions: %s\n", runs.size(), clients,
                    sub.error().message.c_str());
        std::printf("          (gmr-server --send-budget 0 turns admission off to overload it on purpose)\n");
        clients = static_cast<int>(runs.size());
        break;
      }
      std::fprintf(stderr, "gmr-load: %s\n", sub.error().to_string().c_str());
      return 1;
    }
    rate_in_effect = sub->rate_hz;
    run->subscription = sub->id;
    runs.push_back(std::move(run));
  }
  const double setup_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - setup_started).count();
  std::this_thread::sleep_for(std::chrono::duration<double>(warmup));
  for (auto& r : runs) {
    std::lock_guard lock(r->mutex);
    r->measuring = true;
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  for (auto& r : runs) {
    std::lock_guard lock(r->mutex);
    r->measuring = false;
  }
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  std::vector<std::int64_t> all;
  std::uint64_t frames = 0, gaps = 0, server_dropped = 0, server_sent = 0, server_skipped = 0;
  std::string stats_refused;  // why the server's own figures are missing (a 'read' token)
  for (auto& r : runs) {
    {
      std::lock_guard lock(r->mutex);
      all.insert(all.end(), r->latencies_ns.begin(), r->latencies_ns.end());
      frames += r->frames;
      gaps += r->gaps;
    }
    if (auto st = r->client->stats(); st.ok()) {
      server_dropped += st->frames_dropped;
      server_skipped += st->frames_skipped;
      server_sent += st->frames_sent;
    } else if (stats_refused.empty()) {
      stats_refused = st.error().message;
    }
    (void)r->client->unsubscribe(r->subscription);
  }
  std::uint64_t computed = 0, encoded = 0;
  if (!runs.empty()) {
    if (auto st = runs[0]->client->stats(); st.ok()) {
      computed = st->frames_computed;
      encoded = st->frames_encoded;
    }
  }
  if (!stats_refused.empty()) {
    std::printf("gmr-load: the server's figures below are missing: %s\n", stats_refused.c_str());
  }
  const double max_ms = all.empty() ? 0.0 : static_cast<double>(*std::max_element(all.begin(), all.end())) / 1e6;
  std::printf("gmr-load: %d clients, motion %s, %s, %.1f Hz each, %s stream%s, %.1f s measured\n", clients,
              motion.c_str(), udp ? "UDP" : "TCP", rate_in_effect, shared ? "one shared" : "one",
              shared ? "" : " per client", elapsed);
  std::printf("set-up           %.2f s for %d clients on %s\n", setup_seconds, clients,
              threads > 0 ? (std::to_string(threads) + " shared I/O threads").c_str() : "a thread each");
  std::printf("frames received  %llu (%.1f/s in all, %.1f/s per client; expected %.1f/s per client)\n",
              static_cast<unsigned long long>(frames), static_cast<double>(frames) / elapsed,
              static_cast<double>(frames) / elapsed / clients, rate_in_effect);
  std::printf("latency          p50 %.3f ms  p99 %.3f ms  max %.3f ms\n", percentile(all, 0.50), percentile(all, 0.99),
              max_ms);
  std::uint64_t stale = 0;
  for (const auto& r : runs) stale += r->client->counters().frames_stale;
  std::printf("drops            %.2f/s seen by clients (sequence gaps), %llu dropped by the server in all, "
              "%llu by the clients as older than --max-staleness-ms\n",
              static_cast<double>(gaps) / elapsed, static_cast<unsigned long long>(server_dropped),
              static_cast<unsigned long long>(stale));
  std::printf("server late      %llu ticks skipped in all (the server could not keep the rate)\n",
              static_cast<unsigned long long>(server_skipped));
  std::printf("server work      %llu FK runs, %llu encodings, %llu frames sent (whole run)\n",
              static_cast<unsigned long long>(computed), static_cast<unsigned long long>(encoded),
              static_cast<unsigned long long>(server_sent));
  std::printf("policy           %s\n",
              udp ? "UDP: a frame is dropped whole when its connection has too many datagrams in flight; "
                    "a client drops a frame with a lost fragment"
                  : "TCP: bounded queue per client, latest-frame-wins per subscription, drop counter");
  return 0;
}
