// gmr-load: N clients subscribe to a gmr-server and measure what arrives.
//
//   gmr-load [--host H] [--port P] [--token T] [--tls-ca CA] [--clients N] [--motion M] [--retarget RIG [--own-rigs]]
//            [--seconds S] [--rate HZ] [--udp] [--shared] [--orientations] [--float64] [--threads T]
//            [--server-pid PID] [--start-at EPOCH_S] [--json FILE] [--plot FILE.png]
//   gmr-load --merge A.json B.json ... [--json FILE] [--plot FILE.png]
//
// The clients share T I/O threads (gmr::client::EventLoop) and are set up
// concurrently, so one process drives thousands of them; several processes
// (on one host or several, pointed at the same server at the same time) each
// write --json and `--merge` adds them up.
//
// Reports frames delivered against those due, sequence gaps, latency (server
// send time -> client receive time, both system_clock, so only meaningful on
// one host or with synced clocks) as p50/p99/p99.9/max and a histogram, the
// server's counters over the measured window only, this process's CPU (so
// the reader knows whether the load generator was what saturated) and, with
// --server-pid on the same host, the server's CPU per delivered frame.
#include <CLI/CLI.hpp>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <cstdio>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "connect_options.h"
#include "gmr/client/client.h"
#include "gmr/core/file_util.h"
#include "report.h"

namespace {

using gmr::load::Histogram;
using gmr::load::LoadResult;

std::atomic<bool> g_measuring{false};

// One latency histogram per thread that receives frames (the client
// library's I/O threads), merged at the end.
struct ThreadHistogram {
  std::mutex mutex;
  Histogram histogram;
  Histogram server_wait;
};
std::mutex g_histograms_mutex;
std::vector<std::unique_ptr<ThreadHistogram>> g_histograms;

ThreadHistogram& this_threads_histogram() {
  thread_local ThreadHistogram* mine = nullptr;
  if (mine == nullptr) {
    std::lock_guard lock(g_histograms_mutex);
    g_histograms.push_back(std::make_unique<ThreadHistogram>());
    mine = g_histograms.back().get();
  }
  return *mine;
}

struct ClientRun {
  std::unique_ptr<gmr::client::Client> client;
  std::uint32_t subscription = 0;
  double rate_hz = 0;
  // Written by this client's frame callbacks, which do not overlap.
  std::atomic<std::uint64_t> frames{0};
  std::atomic<std::uint64_t> gaps{0};
  std::uint64_t last_sequence = 0;
  bool seen = false;
  // The server's per-connection counters at the window's start.
  gmr::client::ServerCounters before;
  // This subscriber's own tail (report.h, "one sample per subscriber").
  std::mutex tail_mutex;
  gmr::load::CoarseHistogram latency, server_wait;

  void on_frame(const gmr::client::ReceivedFrame& f) {
    if (g_measuring.load(std::memory_order_relaxed)) {
      if (seen && f.sequence > last_sequence + 1)
        gaps.fetch_add(f.sequence - last_sequence - 1, std::memory_order_relaxed);
      frames.fetch_add(1, std::memory_order_relaxed);
      const std::int64_t latency_ns = f.receive_time_ns - f.server_send_time_ns;
      const std::int64_t wait_ns = f.server_write_time_ns - f.server_send_time_ns;
      {
        ThreadHistogram& h = this_threads_histogram();
        std::lock_guard lock(h.mutex);
        h.histogram.add(latency_ns);
        if (f.server_write_time_ns != 0) h.server_wait.add(wait_ns);
      }
      std::lock_guard lock(tail_mutex);
      latency.add(latency_ns);
      if (f.server_write_time_ns != 0) server_wait.add(wait_ns);
    }
    seen = true;
    last_sequence = f.sequence;
  }
};

// Runs fn(0..n-1) on `workers` threads; stops handing out work once fn
// returns false.
void parallel_for(std::size_t n, unsigned workers, const std::function<bool(std::size_t)>& fn) {
  std::atomic<std::size_t> next{0};
  std::atomic<bool> stop{false};
  std::vector<std::thread> pool;
  for (unsigned w = 0; w < std::max(1u, workers); ++w) {
    pool.emplace_back([&] {
      for (std::size_t i; !stop && (i = next++) < n;) {
        if (!fn(i)) stop = true;
      }
    });
  }
  for (auto& t : pool) t.join();
}

double cpu_seconds(const timeval& tv) { return static_cast<double>(tv.tv_sec) + static_cast<double>(tv.tv_usec) / 1e6; }

// utime + stime of a process, in seconds, or -1 when /proc cannot tell.
double process_cpu_seconds(int pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string stat;
  if (!std::getline(in, stat)) return -1;
  // The command name (field 2) is in parentheses and may hold spaces.
  const auto close = stat.rfind(')');
  if (close == std::string::npos) return -1;
  std::istringstream fields(stat.substr(close + 2));
  std::string f;
  unsigned long long utime = 0, stime = 0;
  for (int field = 3; field <= 15 && fields >> f; ++field) {
    if (field == 14) utime = std::stoull(f);
    if (field == 15) stime = std::stoull(f);
  }
  return static_cast<double>(utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

int finish(const LoadResult& r, const std::string& json, const std::string& png) {
  std::fputs(gmr::load::describe(r).c_str(), stdout);
  int rc = 0;
  if (!json.empty()) {
    if (auto st = gmr::write_file_atomic(json, gmr::load::to_json(r)); !st.ok()) {
      std::fprintf(stderr, "gmr-load: %s\n", st.error().to_string().c_str());
      rc = 1;
    }
  }
  if (!png.empty()) {
    if (const std::string err = gmr::load::plot(r, png); !err.empty()) {
      std::fprintf(stderr, "gmr-load: no plot: %s\n", err.c_str());
      rc = 1;
    } else {
      std::printf("plot             %s\n", png.c_str());
    }
  }
  return rc;
}

// Raises this process's open-files limit to what `clients` need: two
// descriptors each (its TCP connection, and the UDP socket every client
// opens), and a margin for the process. Empty, or why it cannot.
std::string fit_open_files(int clients) {
  const auto need = static_cast<rlim_t>(clients) * 2 + 64;
  rlimit lim{};
  if (::getrlimit(RLIMIT_NOFILE, &lim) != 0 || lim.rlim_cur == RLIM_INFINITY || lim.rlim_cur >= need) return {};
  if (lim.rlim_max != RLIM_INFINITY && lim.rlim_max < need) {
    return std::to_string(clients) + " clients need about " + std::to_string(need) +
           " open files (a TCP and a UDP socket each) and this process may open at most " +
           std::to_string(lim.rlim_max) +
           " (ulimit -Hn): run several gmr-load processes with the same --start-at and add up their --json "
           "with --merge, or raise the hard limit";
  }
  lim.rlim_cur = need;
  if (::setrlimit(RLIMIT_NOFILE, &lim) != 0) {
    return "cannot raise the open-files limit to " + std::to_string(need) + " for " + std::to_string(clients) +
           " clients: " + std::strerror(errno);
  }
  return {};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"gmr-load: load-test a gmr-server with N streaming clients"};
  gmr::client::ClientOptions connect_options;
  int clients = 10;
  std::string motion;
  double seconds = 5.0;
  double warmup = 0.5;
  double rate = 0.0;
  bool udp = false, shared = false, orientations = false, float64 = false;
  // Thousands subscribing to a server already busy with the first ones'
  // frames wait behind them: a longer wait for each reply than a command's.
  connect_options.timeout = std::chrono::milliseconds(30000);
  gmr::cli::add_connect_options(app, connect_options);
  app.add_option("--clients", clients, "Connections, one subscription each")
      ->capture_default_str()
      ->check(CLI::Range(1, 20000));
  app.add_option("--motion", motion, "Motion to stream, looped (default: the first in the server's list)");
  std::string retarget_rig;
  app.add_option("--retarget", retarget_rig,
                 "Each client's view retargeted onto this library motion's skeleton (docs/retarget.md) before it "
                 "subscribes: what a retargeted subscription costs the server");
  bool own_rigs = false;
  app.add_flag("--own-rigs", own_rigs,
               "With --retarget: each client's rig its own (its root placed k nm apart for client k), so no two "
               "views of a live source share a replay: the worst case");
  app.add_option("--seconds", seconds, "Measurement time")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--warmup", warmup, "Seconds ignored after the last client subscribed")->capture_default_str();
  app.add_option("--rate", rate, "Output rate in Hz (0: the motion's rate)")->capture_default_str();
  app.add_flag("--udp", udp, "Frames over UDP");
  app.add_flag("--shared", shared, "All clients join one shared stream (one FK and encoding per tick)");
  bool multicast = false;
  app.add_flag("--multicast", multicast,
               "All clients join one shared stream over the server's multicast group (gmr-server "
               "--multicast-group): the server sends each frame once; frames count as delivered where the group "
               "reaches the clients, and the server's CPU is per frame sent to the group");
  app.add_flag("--orientations", orientations, "Send orientations too");
  app.add_flag("--float64", float64, "Send float64 numbers");
  unsigned threads = 2;
  app.add_option("--threads", threads, "I/O threads all the clients share (0: one per client)")->capture_default_str();
  unsigned setup_threads = 16;
  app.add_option("--setup-threads", setup_threads, "Clients connecting and subscribing at once")
      ->capture_default_str()
      ->check(CLI::Range(1, 256));
  int max_staleness_ms = 0;
  app.add_option("--max-staleness-ms", max_staleness_ms,
                 "Each subscription's staleness bound: older frames are dropped by the server and the clients, and "
                 "counted (0: none, so every frame's latency is measured)")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
  int server_pid = 0;
  app.add_option("--server-pid", server_pid,
                 "The server's process id, on this host: report its CPU over the window and per delivered frame");
  double start_at = 0;
  app.add_option("--start-at", start_at,
                 "Open the measured window at this time (seconds since the Unix epoch, after set-up and warm-up): "
                 "gmr-load processes given the same time measure the same window, for --merge");
  std::string json, png;
  std::vector<std::string> merge_files;
  app.add_option("--json", json, "Also write the result as JSON (for --merge and scripts)");
  app.add_option("--plot", png, "Also plot the latency distribution as a PNG (gnuplot)");
  app.add_option("--merge", merge_files, "Merge the --json results of runs made at the same time, and report them")
      ->check(CLI::ExistingFile);
  CLI11_PARSE(app, argc, argv);

  if (!merge_files.empty()) {
    std::vector<LoadResult> runs;
    try {
      for (const auto& f : merge_files) {
        std::ifstream in(f);
        std::stringstream text;
        text << in.rdbuf();
        runs.push_back(gmr::load::from_json(text.str(), f));
      }
      return finish(gmr::load::merge(runs), json, png);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "gmr-load: %s\n", e.what());
      return 1;
    }
  }

  gmr::client::SubscribeOptions so;
  so.loop = true;
  so.rate_hz = rate;
  so.udp = udp;
  so.shared = shared || multicast;
  so.multicast = multicast;
  so.orientations = orientations;
  so.float64 = float64;
  so.max_staleness = std::chrono::milliseconds(max_staleness_ms);
  if (const std::string why = fit_open_files(clients); !why.empty()) {
    std::fprintf(stderr, "gmr-load: %s\n", why.c_str());
    return 1;
  }
  if (threads > 0) connect_options.loop = std::make_shared<gmr::client::EventLoop>(threads);

  const auto setup_started = std::chrono::steady_clock::now();
  std::vector<std::unique_ptr<ClientRun>> runs(static_cast<std::size_t>(clients));
  std::mutex error_mutex;
  std::string error;      // the first failure, which ends the set-up
  std::string admission;  // the server's admission control refused one
  auto connect_one = [&](std::size_t i) -> std::unique_ptr<ClientRun> {
    auto run = std::make_unique<ClientRun>();
    gmr::client::ClientOptions co = connect_options;
    co.client_name = "gmr-load " + std::to_string(i);
    auto c = gmr::client::Client::connect(co);
    if (!c.ok()) {
      std::lock_guard lock(error_mutex);
      if (error.empty()) error = "client " + std::to_string(i) + ": " + c.error().to_string();
      return nullptr;
    }
    run->client = std::move(c).value();
    return run;
  };
  // The first client alone: it picks the motion and proves the server is there.
  runs[0] = connect_one(0);
  if (!runs[0]) {
    std::fprintf(stderr, "gmr-load: %s\n", error.c_str());
    return 1;
  }
  if (motion.empty()) {
    auto list = runs[0]->client->list_motions();
    if (!list.ok() || list->empty()) {
      std::fprintf(stderr, "gmr-load: %s\n",
                   list.ok() ? "the server has no motions" : list.error().to_string().c_str());
      return 1;
    }
    motion = list->front().name;
  }
  // Two phases: every client connects, makes its view and registers its UDP
  // endpoint while the server is still idle; then all subscribe. (Set up one
  // by one, the last clients' requests and registrations would queue behind
  // the frames of the first thousands.)
  std::vector<std::uint32_t> views(runs.size(), 0);
  gmr::Skeleton rig;
  if (!retarget_rig.empty()) {
    auto s = runs[0]->client->skeleton(retarget_rig);
    if (!s.ok()) {
      std::fprintf(stderr, "gmr-load: --retarget %s: %s\n", retarget_rig.c_str(), s.error().to_string().c_str());
      return 1;
    }
    rig = std::move(s).value();
  }
  auto prepare_one = [&](std::size_t i) -> bool {
    if (!runs[i]) runs[i] = connect_one(i);
    if (!runs[i]) return false;
    ClientRun* r = runs[i].get();
    auto view = r->client->create_view(motion);
    if (!view.ok()) {
      std::lock_guard lock(error_mutex);
      if (error.empty()) error = view.error().to_string();
      return false;
    }
    views[i] = view->id;
    if (!retarget_rig.empty()) {
      gmr::Skeleton own = rig;
      if (own_rigs) {
        auto joints = rig.joints();
        joints[static_cast<std::size_t>(rig.roots()[0])].offset.x() += 1e-9 * static_cast<double>(i);
        own = gmr::Skeleton::create(std::move(joints)).value();
      }
      if (auto on_rig = r->client->retarget(view->id, own); !on_rig.ok()) {
        std::lock_guard lock(error_mutex);
        if (error.empty()) error = "client " + std::to_string(i) + ": " + on_rig.error().to_string();
        return false;
      }
    }
    if (udp) {
      if (gmr::Status s = r->client->register_udp(); !s.ok()) {
        std::lock_guard lock(error_mutex);
        if (error.empty()) error = "client " + std::to_string(i) + ": " + s.error().to_string();
        return false;
      }
    }
    return true;
  };
  auto subscribe_one = [&](std::size_t i) -> bool {
    if (!runs[i] || views[i] == 0) return false;
    ClientRun* r = runs[i].get();
    auto sub = r->client->subscribe(views[i], so, [r](const gmr::client::ReceivedFrame& f) { r->on_frame(f); });
    if (!sub.ok()) {
      std::lock_guard lock(error_mutex);
      if (sub.error().message.find("RESOURCE_EXHAUSTED") != std::string::npos) {
        if (admission.empty()) admission = sub.error().message;
      } else if (error.empty()) {
        error = sub.error().to_string();
      }
      runs[i].reset();
      return false;
    }
    r->rate_hz = sub->rate_hz;
    r->subscription = sub->id;
    return true;
  };
  parallel_for(runs.size(), setup_threads, prepare_one);
  if (error.empty()) parallel_for(runs.size(), setup_threads, subscribe_one);
  if (!error.empty()) {
    std::fprintf(stderr, "gmr-load: %s\n", error.c_str());
    return 1;
  }
  // Admission control: measure the clients the server took.
  std::erase_if(runs, [](const auto& r) { return !r || r->subscription == 0; });
  if (!admission.empty()) {
    std::printf("gmr-load: the server admitted %zu of %d subscriptions: %s\n", runs.size(), clients, admission.c_str());
    std::printf("          (gmr-server --send-budget 0 turns admission off to overload it on purpose)\n");
  }
  if (runs.empty()) return 1;
  LoadResult result;
  result.clients = runs.size();
  result.motion = motion;
  result.transport = multicast ? "multicast" : udp ? "udp" : "tcp";
  result.shared = shared || multicast;
  result.rate_hz = runs.front()->rate_hz;
  result.threads = threads;
  result.setup_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - setup_started).count();
  std::this_thread::sleep_for(std::chrono::duration<double>(warmup));
  if (start_at > 0) {
    const auto at = std::chrono::system_clock::time_point(
        std::chrono::duration_cast<std::chrono::system_clock::duration>(std::chrono::duration<double>(start_at)));
    const double late = std::chrono::duration<double>(std::chrono::system_clock::now() - at).count();
    if (late > 0) {
      std::fprintf(stderr, "gmr-load: set-up and warm-up ended %.2f s after --start-at: the window opens late\n", late);
    }
    std::this_thread::sleep_until(at);
  }

  // The window: the server's counters just before and just after it, one
  // request each (server-wide counters: a saturated server answers N
  // per-connection requests only slowly, and frames sent meanwhile would count).
  std::string stats_refused;
  auto snapshot = [&](gmr::client::ServerCounters& into) {
    auto st = runs.front()->client->stats();
    if (!st.ok()) {
      if (stats_refused.empty()) stats_refused = st.error().message;
      return false;
    }
    into = *st;
    return true;
  };
  gmr::client::ServerCounters before, after;
  bool have_server = snapshot(before);
  rusage usage_before{}, usage_after{};
  ::getrusage(RUSAGE_SELF, &usage_before);
  const double server_cpu_before = server_pid > 0 ? process_cpu_seconds(server_pid) : -1;
  g_measuring = true;
  const auto t0 = std::chrono::steady_clock::now();
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  g_measuring = false;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double server_cpu_after = server_pid > 0 ? process_cpu_seconds(server_pid) : -1;
  ::getrusage(RUSAGE_SELF, &usage_after);
  have_server = have_server && snapshot(after);

  result.cpu_user_seconds = cpu_seconds(usage_after.ru_utime) - cpu_seconds(usage_before.ru_utime);
  result.cpu_system_seconds = cpu_seconds(usage_after.ru_stime) - cpu_seconds(usage_before.ru_stime);
  if (server_cpu_before >= 0 && server_cpu_after >= 0) result.server_cpu_seconds = server_cpu_after - server_cpu_before;
  for (const auto& r : runs) {
    std::lock_guard lock(r->tail_mutex);
    if (r->latency.count() > 0) {
      result.subscriber_p99_latency.add(static_cast<std::int64_t>(r->latency.quantile_ns(0.99)));
    }
    if (r->server_wait.count() > 0) {
      result.subscriber_p99_server_wait.add(static_cast<std::int64_t>(r->server_wait.quantile_ns(0.99)));
    }
  }
  for (const auto& r : runs) {
    result.frames += r->frames.load();
    result.gaps += r->gaps.load();
    result.stale += r->client->counters().frames_stale;
  }
  {
    std::lock_guard lock(g_histograms_mutex);
    for (const auto& h : g_histograms) {
      std::lock_guard hl(h->mutex);
      result.latency.add(h->histogram);
      result.server_wait.add(h->server_wait);
    }
  }
  result.have_server = have_server;
  if (have_server) {
    result.server_sent = after.frames_sent_total - before.frames_sent_total;
    result.server_dropped = after.frames_dropped_total - before.frames_dropped_total;
    result.server_skipped = after.frames_skipped_total - before.frames_skipped_total;
    result.server_computed = after.frames_computed - before.frames_computed;
    result.server_encoded = after.frames_encoded - before.frames_encoded;
    result.server_late_total = after.frames_skipped_total - before.frames_skipped_total;
    result.server_io_threads = after.io_threads;
    result.server_multicast_sent = after.multicast_frames_sent - before.multicast_frames_sent;
  } else {
    std::printf("gmr-load: the server's figures below are missing: %s\n", stats_refused.c_str());
  }
  parallel_for(runs.size(), setup_threads, [&](std::size_t i) {
    (void)runs[i]->client->unsubscribe(runs[i]->subscription);
    return true;
  });
  std::printf("policy           %s\n",
              multicast ? "multicast: each frame sent once to the group; a client drops a frame with a lost fragment"
              : udp     ? "UDP: a frame is dropped whole when its connection has too many datagrams in flight; "
                          "a client drops a frame with a lost fragment"
                        : "TCP: bounded queue per client, latest-frame-wins per subscription, drop counter");
  return finish(result, json, png);
}
