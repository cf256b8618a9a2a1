// gmr-soak: a long run against a gmr-server with churn and hostile clients,
// sampling the server's memory, descriptors and the latency its steady
// clients see (docs/reliability.md, "Soak"). bench/soak.sh starts the server
// and this program; the figures go to docs/reliability.md.
//
//   gmr-soak --port P --server-pid PID [--clients 1000] [--seconds 600]
//            [--rate 30] [--churn 10] [--hostile 5] [--sample 10] [--csv FILE]
//            [--token T] [--round-two 2 --http-port H --publish-token P --read-token R
//             [--nats-port N --nats-user U --nats-password W]]
//   gmr-soak --write-library DIR     (the round-two library, then exit)
//
// Steady clients: `clients` connections, each with one view (half of them
// re-rooted or seen from a joint) and one looping subscription (a quarter
// over UDP, a quarter on shared streams). Churn: `churn` times a second one
// of them closes and a new one connects, edits and subscribes in its place.
// Hostile: `hostile` times a second one of: a connection that never says
// Hello, garbage bytes, a huge length prefix, a declared 4 MiB message that
// never comes, a subscriber at 2 kHz that never reads, a burst of requests
// that do not parse, forged UDP registrations. Each sample prints the
// server's RSS and open descriptors and the steady clients' frames and
// latency since the previous sample; the summary compares the first and last
// minutes. Round two (round_two.h): `--round-two` more attacks a second, of
// twelve kinds, on a thread of their own, while /healthz and /readyz are
// probed every second; the summary says what each attack met and the
// server's own counters of refusals.
#include <arpa/inet.h>
#include <dirent.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <deque>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "connect_options.h"
#include "gmr/client/client.h"
#include "gmr/stream/v1/stream.pb.h"
#include "gmr/wire/framing.h"
#include "gmr/wire/udp.h"
#include "round_two.h"
#include "sockets.h"

namespace {

namespace pb = ::gmr::stream::v1;
using namespace gmr::soak;
using Clock = std::chrono::steady_clock;

// ---------------------------------------------------------------- the server process

std::uint64_t process_kb(int pid, const char* key) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string k;
  while (in >> k) {
    if (k == key) {
      std::uint64_t kb = 0;
      in >> kb;
      return kb;
    }
    std::string rest;
    std::getline(in, rest);
  }
  return 0;
}

int open_descriptors(int pid) {
  DIR* d = ::opendir(("/proc/" + std::to_string(pid) + "/fd").c_str());
  if (d == nullptr) return -1;
  int n = 0;
  while (const dirent* e = ::readdir(d)) {
    if (e->d_name[0] != '.') ++n;
  }
  ::closedir(d);
  return n;
}

// ---------------------------------------------------------------- steady clients

// What one client's frames showed since the last sample (shared with its
// callback, which may outlive the slot by a frame).
struct Window {
  std::mutex mutex;
  std::vector<std::int64_t> latencies_ns;
  std::uint64_t frames = 0, gaps = 0;
  std::uint64_t last_sequence = 0;
  bool any = false;
};

struct Slot {
  std::unique_ptr<gmr::client::Client> client;
  std::shared_ptr<Window> window;
};

struct Figures {
  std::atomic<std::uint64_t> connects{0}, connect_failures{0}, hostile{0};
  std::mutex mutex;
  std::vector<double> connect_ms;     // connect + view + edit + subscribe, this window
  std::vector<std::string> failures;  // the first few, for the report
};

const std::vector<std::string> kMotions = {"walk", "wave", "jump", "turn"};
const std::vector<std::string> kJoints = {"head", "l_hand", "r_toe", "chest", "l_knee"};

// A new steady client: connect, a view, maybe an edit, one subscription.
Slot start_client(const gmr::client::ClientOptions& base, double rate, std::mt19937_64& rng, Figures& figures) {
  Slot slot;
  const auto t0 = Clock::now();
  auto fail = [&](const std::string& what) {
    ++figures.connect_failures;
    std::lock_guard lock(figures.mutex);
    if (figures.failures.size() < 10) figures.failures.push_back(what);
    return Slot{};
  };
  gmr::client::ClientOptions o = base;
  o.client_name = "gmr-soak";
  auto c = gmr::client::Client::connect(o);
  if (!c.ok()) return fail(c.error().to_string());
  auto v = (*c)->create_view(kMotions[rng() % kMotions.size()]);
  if (!v.ok()) return fail(v.error().to_string());
  const std::string joint = kJoints[rng() % kJoints.size()];
  switch (rng() % 4) {
    case 0: {
      auto e = (*c)->shift_root(v->id, joint);
      if (!e.ok()) return fail(e.error().to_string());
      break;
    }
    case 1: {
      auto e = (*c)->set_coordinates(v->id, joint);
      if (!e.ok()) return fail(e.error().to_string());
      break;
    }
    default:
      break;
  }
  gmr::client::SubscribeOptions so;
  so.loop = true;
  so.rate_hz = rate;
  const auto kind = rng() % 4;
  so.udp = kind == 0;
  so.shared = kind == 1;
  so.orientations = rng() % 2 == 0;
  auto window = std::make_shared<Window>();
  auto sub = (*c)->subscribe(v->id, so, [window](const gmr::client::ReceivedFrame& f) {
    std::lock_guard lock(window->mutex);
    if (window->any && f.sequence > window->last_sequence + 1) window->gaps += f.sequence - window->last_sequence - 1;
    window->any = true;
    window->last_sequence = f.sequence;
    ++window->frames;
    window->latencies_ns.push_back(f.receive_time_ns - f.server_send_time_ns);
  });
  if (!sub.ok()) return fail(sub.error().to_string());
  ++figures.connects;
  {
    std::lock_guard lock(figures.mutex);
    figures.connect_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
  }
  slot.client = std::move(c).value();
  slot.window = std::move(window);
  return slot;
}

// ---------------------------------------------------------------- hostile clients

// Connections the hostile side holds open until their deadline.
struct Held {
  int fd;
  Clock::time_point until;
};

class Hostile {
 public:
  Hostile(std::string host, std::uint16_t port, std::uint16_t udp_port)
      : host_(std::move(host)), port_(port), udp_port_(udp_port) {}
  ~Hostile() {
    for (auto& h : held_) ::close(h.fd);
  }

  // One attack, chosen at random; returns its name.
  const char* act(std::mt19937_64& rng) {
    release(false);
    switch (rng() % 7) {
      case 0: {  // silent: never says Hello
        hold(raw_connect(host_, port_), std::chrono::seconds(3));
        return "silent";
      }
      case 1: {  // garbage bytes
        const int fd = raw_connect(host_, port_);
        if (fd >= 0) {
          std::string junk(64, '\0');
          for (auto& ch : junk) ch = static_cast<char>(rng());
          send_all(fd, junk);
          ::close(fd);
        }
        return "garbage";
      }
      case 2: {  // a length prefix far above the cap
        const int fd = raw_connect(host_, port_);
        if (fd >= 0) {
          send_all(fd, std::string("\xff\xff\xff\xff", 4));
          ::close(fd);
        }
        return "huge prefix";
      }
      case 3: {  // 4 MiB announced, 10 bytes sent, held
        const int fd = raw_connect(host_, port_);
        if (fd >= 0) {
          send_all(fd, std::string("\x00\x3f\xff\xff", 4) + std::string(10, 'x'));
          hold(fd, std::chrono::seconds(3));
        }
        return "declared length";
      }
      case 4: {  // subscribes at 2 kHz and never reads
        const int fd = raw_connect(host_, port_, {}, 4096);
        if (fd >= 0) {
          send_request(fd, 1, hello_message("soak: never reads"));
          pb::ClientMessage view;
          view.mutable_create_view()->set_motion("walk");
          send_request(fd, 2, view);
          drain(fd, 4096);
          for (std::uint64_t id = 3; id < 7; ++id) {
            pb::ClientMessage sub;
            sub.mutable_subscribe()->set_view_id(1);
            sub.mutable_subscribe()->set_loop(true);
            sub.mutable_subscribe()->set_rate_hz(2000);
            sub.mutable_subscribe()->set_orientations(true);
            sub.mutable_subscribe()->set_precision(pb::PRECISION_FLOAT64);
            send_request(fd, id, sub);
          }
          hold(fd, std::chrono::seconds(5));
        }
        return "never reads";
      }
      case 5: {  // requests that do not parse
        const int fd = raw_connect(host_, port_);
        if (fd >= 0) {
          std::string burst;
          for (int i = 0; i < 50; ++i) burst += gmr::wire::frame_bytes(std::string(20, static_cast<char>(0xff)));
          send_all(fd, burst);
          ::close(fd);
        }
        return "bad requests";
      }
      default: {  // forged UDP registrations with guessed tokens
        const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
        sockaddr_in addr{};
        addr.sin_family = AF_INET;
        addr.sin_port = htons(udp_port_);
        ::inet_pton(AF_INET, host_.c_str(), &addr.sin_addr);
        for (int i = 0; i < 20; ++i) {
          gmr::wire::UdpToken token;
          for (auto& b : token) b = static_cast<std::uint8_t>(rng());
          const std::string d = gmr::wire::make_register_datagram(token);
          ::sendto(fd, d.data(), d.size(), 0, reinterpret_cast<sockaddr*>(&addr), sizeof addr);
        }
        ::close(fd);
        return "forged udp";
      }
    }
  }

  // Closes held connections past their deadline (all, with `all`).
  void release(bool all) {
    const auto now = Clock::now();
    while (!held_.empty() && (all || held_.front().until <= now)) {
      ::close(held_.front().fd);
      held_.pop_front();
    }
  }

 private:
  void hold(int fd, Clock::duration d) {
    if (fd >= 0) held_.push_back(Held{fd, Clock::now() + d});
  }
  std::string host_;
  std::uint16_t port_, udp_port_;
  std::deque<Held> held_;  // nearly in deadline order (holds are 3 or 5 s): closed at most 2 s late
};

// ---------------------------------------------------------------- report

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  const auto k = static_cast<std::size_t>(p * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

struct Sample {
  double t = 0;
  double rss_mb = 0;
  int fds = 0;
  double frames_per_s = 0, gaps_per_s = 0;
  double p50_ms = 0, p99_ms = 0, max_ms = 0;
  double connect_p99_ms = 0;
  std::uint64_t connects = 0, failures = 0, hostile = 0;
};

// Least-squares slope of RSS over time (MB per minute).
double slope_mb_per_minute(const std::vector<Sample>& s) {
  if (s.size() < 2) return 0.0;
  double mt = 0, mr = 0;
  for (const auto& x : s) {
    mt += x.t;
    mr += x.rss_mb;
  }
  mt /= static_cast<double>(s.size());
  mr /= static_cast<double>(s.size());
  double num = 0, den = 0;
  for (const auto& x : s) {
    num += (x.t - mt) * (x.rss_mb - mr);
    den += (x.t - mt) * (x.t - mt);
  }
  return den == 0 ? 0.0 : num / den * 60.0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"gmr-soak: churn and hostile clients against a gmr-server, its memory and descriptors sampled"};
  gmr::client::ClientOptions connect_options;
  int server_pid = 0, clients = 1000;
  double seconds = 600, rate = 30, churn = 10, hostile_rate = 5, sample_every = 10;
  std::string csv;
  gmr::cli::add_connect_options(app, connect_options);
  app.add_option("--server-pid", server_pid, "The gmr-server's process id (for RSS and descriptors)");
  app.add_option("--clients", clients, "Steady clients")->capture_default_str()->check(CLI::Range(1, 20000));
  app.add_option("--seconds", seconds, "Length of the run")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--rate", rate, "Frames per second per steady client")->capture_default_str();
  app.add_option("--churn", churn, "Clients replaced per second")->capture_default_str();
  app.add_option("--hostile", hostile_rate, "Hostile actions per second")->capture_default_str();
  app.add_option("--sample", sample_every, "Seconds between samples")->capture_default_str();
  app.add_option("--csv", csv, "Write the samples here too");
  gmr::soak::RoundTwoSettings two;
  double round_two_rate = 0;
  std::string library_dir;
  app.add_option("--round-two", round_two_rate, "Round-two attacks per second (0: none)")->capture_default_str();
  app.add_option("--http-port", two.http_port, "The server's HTTP port (round two, and /healthz probes)");
  app.add_option("--publish-token", two.publish_token, "A 'publish' token (round two's publishers)");
  app.add_option("--read-token", two.read_token, "A 'read' token (round two's JSON block asker)");
  app.add_option("--nats-port", two.nats_port, "The NATS server the gmr-server relays through (round two)");
  app.add_option("--nats-user", two.nats_user, "Its user (the rogue relay has the credentials, not the secret)");
  app.add_option("--nats-password", two.nats_password, "Its password");
  app.add_option("--write-library", library_dir, "Write round two's library (demo motions + chain.bvh) here and exit");
  CLI11_PARSE(app, argc, argv);
  if (!library_dir.empty()) {
    std::string error;
    if (!gmr::soak::write_library(library_dir, &error)) {
      std::fprintf(stderr, "gmr-soak: %s\n", error.c_str());
      return 1;
    }
    return 0;
  }
  if (server_pid <= 0) {
    std::fprintf(stderr, "gmr-soak: --server-pid is required\n");
    return 1;
  }
  connect_options.timeout = std::chrono::seconds(10);
  two.host = connect_options.host;
  two.port = connect_options.port;
  two.control_token = connect_options.auth_token;

  std::mt19937_64 rng(20261123);
  Figures figures;
  std::printf("gmr-soak: server pid %d, %d steady clients at %.0f Hz, churn %.1f/s, hostile %.1f/s, %.0f s\n",
              server_pid, clients, rate, churn, hostile_rate, seconds);
  const double rss_start = static_cast<double>(process_kb(server_pid, "VmRSS:")) / 1024.0;
  std::vector<Slot> slots;
  slots.reserve(static_cast<std::size_t>(clients));
  const auto setup0 = Clock::now();
  for (int i = 0; i < clients; ++i) slots.push_back(start_client(connect_options, rate, rng, figures));
  const double setup_s = std::chrono::duration<double>(Clock::now() - setup0).count();
  std::printf("set up %d clients in %.1f s (%llu failed); server RSS %.1f MB before, %.1f MB now\n", clients, setup_s,
              static_cast<unsigned long long>(figures.connect_failures.load()), rss_start,
              static_cast<double>(process_kb(server_pid, "VmRSS:")) / 1024.0);
  if (slots.empty() || !slots[0].client) {
    std::fprintf(stderr, "gmr-soak: cannot start clients\n");
    return 1;
  }
  const std::uint16_t udp_port = slots[0].client->hello().udp_port;

  // Hostile actions on their own thread.
  std::atomic<bool> running{true};
  std::thread hostile_thread([&] {
    std::mt19937_64 hrng(7);
    Hostile h(connect_options.host, connect_options.port, udp_port);
    const auto period = std::chrono::duration<double>(1.0 / std::max(hostile_rate, 1e-3));
    auto next = Clock::now();
    while (running) {
      if (hostile_rate > 0) {
        h.act(hrng);
        ++figures.hostile;
      }
      next += std::chrono::duration_cast<Clock::duration>(period);
      std::this_thread::sleep_until(next);
    }
    h.release(true);
  });
  // Round two on a thread of its own, and the health probes a Kubernetes
  // kubelet would make, once a second.
  std::mutex tallies_mutex;
  std::map<std::string, gmr::soak::Tally> tallies;
  std::thread round_two_thread([&] {
    if (round_two_rate <= 0) return;
    std::mt19937_64 rrng(11);
    gmr::soak::RoundTwo attacks(two);
    const auto period = std::chrono::duration<double>(1.0 / round_two_rate);
    auto next = Clock::now();
    while (running) {
      attacks.act(rrng);
      ++figures.hostile;
      next += std::chrono::duration_cast<Clock::duration>(period);
      while (running && Clock::now() < next) {
        attacks.tick();
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
      std::lock_guard lock(tallies_mutex);
      tallies = attacks.tallies();
    }
    attacks.tick(true);
    std::lock_guard lock(tallies_mutex);
    tallies = attacks.tallies();
  });
  std::atomic<std::uint64_t> probes{0}, probes_failed{0};
  std::thread probe_thread([&] {
    if (two.http_port == 0) return;
    while (running) {
      for (const char* path : {"/healthz", "/readyz"}) {
        ++probes;
        if (gmr::soak::http_status(connect_options.host, two.http_port, path) != 200) ++probes_failed;
      }
      std::this_thread::sleep_for(std::chrono::seconds(1));
    }
  });

  std::printf("%7s %9s %6s %10s %8s %8s %8s %8s %10s %8s %8s %8s\n", "t(s)", "RSS(MB)", "fds", "frames/s", "gaps/s",
              "p50(ms)", "p99(ms)", "max(ms)", "join99(ms)", "joined", "failed", "hostile");
  std::vector<Sample> samples;
  const auto t0 = Clock::now();
  auto next_sample = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(sample_every));
  auto last_sample = t0;
  const auto churn_period = std::chrono::duration<double>(1.0 / std::max(churn, 1e-3));
  auto next_churn = t0;
  const auto end = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  std::uint64_t connects_before = figures.connects, failures_before = figures.connect_failures;
  std::uint64_t hostile_before = 0;
  Window retired;  // the windows of replaced clients since the last sample
  while (Clock::now() < end) {
    if (churn > 0 && Clock::now() >= next_churn) {
      auto& s = slots[rng() % slots.size()];
      s.client.reset();  // closes; what its window saw still counts
      if (s.window) {
        std::lock_guard lock(s.window->mutex);
        retired.latencies_ns.insert(retired.latencies_ns.end(), s.window->latencies_ns.begin(),
                                    s.window->latencies_ns.end());
        retired.frames += s.window->frames;
        retired.gaps += s.window->gaps;
      }
      s = start_client(connect_options, rate, rng, figures);
      next_churn += std::chrono::duration_cast<Clock::duration>(churn_period);
    }
    if (Clock::now() >= next_sample) {
      const auto now = Clock::now();
      const double dt = std::chrono::duration<double>(now - last_sample).count();
      last_sample = now;
      std::vector<double> lat;
      for (auto ns : retired.latencies_ns) lat.push_back(static_cast<double>(ns) / 1e6);
      std::uint64_t frames = retired.frames, gaps = retired.gaps;
      retired.latencies_ns.clear();
      retired.frames = retired.gaps = 0;
      for (auto& s : slots) {
        if (!s.window) continue;
        std::lock_guard lock(s.window->mutex);
        for (auto ns : s.window->latencies_ns) lat.push_back(static_cast<double>(ns) / 1e6);
        frames += s.window->frames;
        gaps += s.window->gaps;
        s.window->latencies_ns.clear();
        s.window->frames = s.window->gaps = 0;
      }
      std::vector<double> joins;
      {
        std::lock_guard lock(figures.mutex);
        joins.swap(figures.connect_ms);
      }
      Sample x;
      x.t = std::chrono::duration<double>(now - t0).count();
      x.rss_mb = static_cast<double>(process_kb(server_pid, "VmRSS:")) / 1024.0;
      x.fds = open_descriptors(server_pid);
      x.frames_per_s = static_cast<double>(frames) / dt;
      x.gaps_per_s = static_cast<double>(gaps) / dt;
      x.p50_ms = percentile(lat, 0.5);
      x.p99_ms = percentile(lat, 0.99);
      x.max_ms = lat.empty() ? 0.0 : *std::max_element(lat.begin(), lat.end());
      x.connect_p99_ms = percentile(joins, 0.99);
      x.connects = figures.connects - connects_before;
      x.failures = figures.connect_failures - failures_before;
      x.hostile = figures.hostile - hostile_before;
      connects_before = figures.connects;
      failures_before = figures.connect_failures;
      hostile_before = figures.hostile;
      samples.push_back(x);
      std::printf("%7.0f %9.1f %6d %10.0f %8.2f %8.3f %8.3f %8.2f %10.1f %8llu %8llu %8llu\n", x.t, x.rss_mb, x.fds,
                  x.frames_per_s, x.gaps_per_s, x.p50_ms, x.p99_ms, x.max_ms, x.connect_p99_ms,
                  static_cast<unsigned long long>(x.connects), static_cast<unsigned long long>(x.failures),
                  static_cast<unsigned long long>(x.hostile));
      std::fflush(stdout);
      next_sample += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(sample_every));
    }
    std::this_thread::sleep_until(std::min(next_churn, next_sample));
  }
  // The server's own counters of what it refused, before everyone leaves.
  const std::string metrics =
      two.http_port != 0 ? gmr::soak::http_get(connect_options.host, two.http_port, "/metrics") : std::string{};
  running = false;
  hostile_thread.join();
  round_two_thread.join();
  probe_thread.join();
  slots.clear();
  std::this_thread::sleep_for(std::chrono::seconds(2));
  const double rss_after = static_cast<double>(process_kb(server_pid, "VmRSS:")) / 1024.0;
  const int fds_after = open_descriptors(server_pid);

  if (!csv.empty()) {
    std::ofstream out(csv);
    out << "t_s,rss_mb,fds,frames_per_s,gaps_per_s,p50_ms,p99_ms,max_ms,join_p99_ms,joined,failed,hostile\n";
    for (const auto& x : samples) {
      out << x.t << ',' << x.rss_mb << ',' << x.fds << ',' << x.frames_per_s << ',' << x.gaps_per_s << ',' << x.p50_ms
          << ',' << x.p99_ms << ',' << x.max_ms << ',' << x.connect_p99_ms << ',' << x.connects << ',' << x.failures
          << ',' << x.hostile << '\n';
    }
  }
  // After the first minute (warm caches, every stream started): the trend.
  std::vector<Sample> settled;
  for (const auto& x : samples) {
    if (x.t >= 60 || samples.size() < 7) settled.push_back(x);
  }
  double rss_min = 1e18, rss_max = 0, p99_max = 0;
  int fds_min = 1 << 30, fds_max = 0;
  for (const auto& x : settled) {
    rss_min = std::min(rss_min, x.rss_mb);
    rss_max = std::max(rss_max, x.rss_mb);
    fds_min = std::min(fds_min, x.fds);
    fds_max = std::max(fds_max, x.fds);
    p99_max = std::max(p99_max, x.p99_ms);
  }
  std::printf(
      "\nsummary of the samples after the first minute (%zu): RSS %.1f-%.1f MB, slope %+.2f MB/min; fds %d-%d; "
      "worst window p99 %.2f ms\n",
      settled.size(), rss_min, rss_max, slope_mb_per_minute(settled), fds_min, fds_max, p99_max);
  std::printf("clients joined %llu, failed %llu; hostile actions %llu\n",
              static_cast<unsigned long long>(figures.connects.load()),
              static_cast<unsigned long long>(figures.connect_failures.load()),
              static_cast<unsigned long long>(figures.hostile.load()));
  for (const auto& f : figures.failures) std::printf("  failure: %s\n", f.c_str());
  if (two.http_port != 0) {
    std::printf("health probes: %llu, %llu not answered 200\n", static_cast<unsigned long long>(probes.load()),
                static_cast<unsigned long long>(probes_failed.load()));
  }
  for (const auto& [attack, tally] : tallies) {
    std::printf("round two, %s: %llu times;", attack.c_str(), static_cast<unsigned long long>(tally.acts));
    for (const auto& [outcome, n] : tally.outcomes) {
      std::printf(" %s %llu;", outcome.c_str(), static_cast<unsigned long long>(n));
    }
    std::printf("\n");
  }
  // The refusal counters and gauges the report quotes.
  std::istringstream lines(metrics);
  for (std::string line; std::getline(lines, line);) {
    static const char* kShown[] = {"gmr_connections_refused_total",
                                   "gmr_hellos_refused_total",
                                   "gmr_live_frames_over_rate_total",
                                   "gmr_relay_messages_refused_total",
                                   "gmr_recordings_cut_total",
                                   "gmr_recordings_refused_total",
                                   "gmr_log_lines_suppressed_total",
                                   "gmr_publications_refused_total",
                                   "gmr_subscriptions_refused_total",
                                   "gmr_buffered_bytes",
                                   "gmr_record_bytes",
                                   "gmr_http_responses_total",
                                   "gmr_request_errors_total",
                                   "gmr_connections "};
    for (const char* shown : kShown) {
      if (line.rfind(shown, 0) == 0) std::printf("  %s\n", line.c_str());
    }
  }
  std::printf("all closed: server RSS %.1f MB (%.1f MB at start), %d descriptors\n", rss_after, rss_start, fds_after);
  return figures.connect_failures.load() == 0 && probes_failed.load() == 0 ? 0 : 2;
}
