#include "report.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <unistd.h>

namespace gmr::load {

// ---- Histogram ----------------------------------------------------------

std::size_t Histogram::bucket_of(std::int64_t ns) {
  if (ns < 64) return ns < 0 ? 0 : static_cast<std::size_t>(ns);
  const auto v = static_cast<std::uint64_t>(ns);
  const int shift = std::bit_width(v) - 1 - kSubBits;
  const std::size_t b = (std::size_t{32} * static_cast<std::size_t>(shift)) + static_cast<std::size_t>(v >> shift);
  return std::min(b, kBuckets - 1);
}

std::int64_t Histogram::bucket_low(std::size_t b) {
  if (b < 64) return static_cast<std::int64_t>(b);
  const std::size_t shift = b / 32 - 1;
  return static_cast<std::int64_t>((b - 32 * shift) << shift);
}

std::int64_t Histogram::bucket_high(std::size_t b) {
  if (b < 64) return static_cast<std::int64_t>(b) + 1;
  const std::size_t shift = b / 32 - 1;
  return static_cast<std::int64_t>((b - 32 * shift + 1) << shift);
}

void Histogram::add(std::int64_t ns) {
  ++counts_[bucket_of(ns)];
  ++count_;
  max_ = std::max(max_, ns);
}

void Histogram::add(const Histogram& other) {
  for (std::size_t b = 0; b < kBuckets; ++b) counts_[b] += other.counts_[b];
  count_ += other.count_;
  max_ = std::max(max_, other.max_);
}

void Histogram::set(std::size_t bucket, std::uint64_t n) {
  count_ += n - counts_[bucket];
  counts_[bucket] = n;
  if (n > 0) max_ = std::max(max_, bucket_high(bucket) - 1);
}

void CoarseHistogram::add(std::int64_t ns) {
  std::size_t b = 0;
  if (ns >= 1024) {
    const auto v = static_cast<std::uint64_t>(ns);
    const int octave = 63 - std::countl_zero(v);  // >= 10
    const auto sub = static_cast<std::size_t>((v >> (octave - 2)) & 3);
    b = std::min(kBuckets - 1, 1 + 4 * static_cast<std::size_t>(octave - 10) + sub);
  }
  ++counts_[b];
  ++count_;
}

double CoarseHistogram::quantile_ns(double q) const {
  if (count_ == 0) return 0.0;
  const auto rank = static_cast<std::uint64_t>(std::ceil(std::clamp(q, 0.0, 1.0) * count_));
  std::uint64_t seen = 0;
  for (std::size_t b = 0; b < kBuckets; ++b) {
    seen += counts_[b];
    if (seen >= std::max<std::uint64_t>(rank, 1)) {
      if (b == 0) return 1024.0;
      const std::size_t octave = 10 + (b - 1) / 4, sub = (b - 1) % 4;
      return std::ldexp(static_cast<double>(5 + sub) / 4.0, static_cast<int>(octave));
    }
  }
  return std::ldexp(1.0, 36);
}

double Histogram::quantile_ns(double q) const {
  if (count_ == 0) return 0;
  if (q >= 1) return static_cast<double>(max_);
  const auto rank = std::max<std::uint64_t>(1, static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(count_))));
  std::uint64_t seen = 0;
  for (std::size_t b = 0; b < kBuckets; ++b) {
    seen += counts_[b];
    if (seen >= rank) {
      const double mid = 0.5 * static_cast<double>(bucket_low(b) + bucket_high(b) - 1);
      return std::min(mid, static_cast<double>(max_));
    }
  }
  return static_cast<double>(max_);
}

// ---- JSON ---------------------------------------------------------------

namespace {

// The histogram's non-empty buckets as [lowest ns, count], and its maximum.
nlohmann::json histogram_json(const Histogram& h) {
  nlohmann::json buckets = nlohmann::json::array();
  for (std::size_t b = 0; b < Histogram::kBuckets; ++b) {
    if (h.at(b) != 0) buckets.push_back({Histogram::bucket_low(b), h.at(b)});
  }
  return {{"max", h.max()}, {"buckets", buckets}};
}

void read_histogram(const nlohmann::json& j, const std::string& what, Histogram& h) {
  for (const auto& b : j.at("buckets")) {
    const auto low = b.at(0).get<std::int64_t>();
    const std::size_t bucket = Histogram::bucket_of(low);
    if (Histogram::bucket_low(bucket) != low) {
      throw std::runtime_error(what + " bucket " + std::to_string(low) + " ns is not a bucket boundary");
    }
    h.set(bucket, b.at(1).get<std::uint64_t>());
  }
}

}  // namespace

std::string to_json(const LoadResult& r) {
  nlohmann::json j;
  j["format"] = "gmr-load 1";
  j["processes"] = r.processes;
  j["clients"] = r.clients;
  j["motion"] = r.motion;
  j["transport"] = r.transport;
  j["shared"] = r.shared;
  j["rate_hz"] = r.rate_hz;
  j["seconds"] = r.seconds;
  j["setup_seconds"] = r.setup_seconds;
  j["frames"] = r.frames;
  j["gaps"] = r.gaps;
  j["stale"] = r.stale;
  j["threads"] = r.threads;
  j["cpu_user_seconds"] = r.cpu_user_seconds;
  j["cpu_system_seconds"] = r.cpu_system_seconds;
  if (r.have_server) {
    j["server"] = {{"frames_sent", r.server_sent},       {"frames_dropped", r.server_dropped},
                   {"frames_skipped", r.server_skipped}, {"frames_computed", r.server_computed},
                   {"frames_encoded", r.server_encoded}, {"frames_skipped_total", r.server_late_total},
                   {"io_threads", r.server_io_threads},  {"multicast_frames_sent", r.server_multicast_sent}};
  }
  if (r.server_cpu_seconds >= 0) j["server_cpu_seconds"] = r.server_cpu_seconds;
  j["latency_ns"] = histogram_json(r.latency);
  if (r.server_wait.count() > 0) j["server_wait_ns"] = histogram_json(r.server_wait);
  if (r.subscriber_p99_latency.count() > 0) {
    j["subscriber_p99_latency_ns"] = histogram_json(r.subscriber_p99_latency);
  }
  if (r.subscriber_p99_server_wait.count() > 0) {
    j["subscriber_p99_server_wait_ns"] = histogram_json(r.subscriber_p99_server_wait);
  }
  // Derived, for scripts (from_json reads the buckets back instead).
  j["delivered_per_second"] = r.seconds > 0 ? static_cast<double>(r.frames) / r.seconds : 0.0;
  j["expected_per_second"] = r.rate_hz * static_cast<double>(r.clients);
  j["latency_ms"] = {{"p50", r.latency.quantile_ns(0.5) / 1e6},
                     {"p99", r.latency.quantile_ns(0.99) / 1e6},
                     {"p99.9", r.latency.quantile_ns(0.999) / 1e6},
                     {"max", static_cast<double>(r.latency.max()) / 1e6}};
  return j.dump(1) + "\n";
}

LoadResult from_json(const std::string& text, const std::string& label) {
  LoadResult r;
  try {
    const nlohmann::json j = nlohmann::json::parse(text);
    if (j.value("format", "") != "gmr-load 1") {
      throw std::runtime_error("not a gmr-load result (\"format\": \"gmr-load 1\" missing)");
    }
    r.processes = j.at("processes").get<int>();
    r.clients = j.at("clients").get<std::uint64_t>();
    r.motion = j.at("motion").get<std::string>();
    r.transport = j.at("transport").get<std::string>();
    if (r.transport != "tcp" && r.transport != "udp" && r.transport != "multicast") {
      throw std::runtime_error("unknown transport '" + r.transport.substr(0, 32) + "'");
    }
    r.shared = j.at("shared").get<bool>();
    r.rate_hz = j.at("rate_hz").get<double>();
    r.seconds = j.at("seconds").get<double>();
    r.setup_seconds = j.at("setup_seconds").get<double>();
    r.frames = j.at("frames").get<std::uint64_t>();
    r.gaps = j.at("gaps").get<std::uint64_t>();
    r.stale = j.at("stale").get<std::uint64_t>();
    r.threads = j.at("threads").get<unsigned>();
    r.cpu_user_seconds = j.at("cpu_user_seconds").get<double>();
    r.cpu_system_seconds = j.at("cpu_system_seconds").get<double>();
    if (j.contains("server")) {
      const auto& s = j.at("server");
      r.have_server = true;
      r.server_sent = s.at("frames_sent").get<std::uint64_t>();
      r.server_dropped = s.at("frames_dropped").get<std::uint64_t>();
      r.server_skipped = s.at("frames_skipped").get<std::uint64_t>();
      r.server_computed = s.at("frames_computed").get<std::uint64_t>();
      r.server_encoded = s.at("frames_encoded").get<std::uint64_t>();
      r.server_late_total = s.at("frames_skipped_total").get<std::uint64_t>();
      r.server_io_threads = s.value("io_threads", 0u);
      r.server_multicast_sent = s.value("multicast_frames_sent", std::uint64_t{0});
    }
    r.server_cpu_seconds = j.value("server_cpu_seconds", -1.0);
    read_histogram(j.at("latency_ns"), "latency", r.latency);
    if (j.contains("server_wait_ns")) read_histogram(j.at("server_wait_ns"), "server wait", r.server_wait);
    if (j.contains("subscriber_p99_latency_ns")) {
      read_histogram(j.at("subscriber_p99_latency_ns"), "subscriber p99 latency", r.subscriber_p99_latency);
    }
    if (j.contains("subscriber_p99_server_wait_ns")) {
      read_histogram(j.at("subscriber_p99_server_wait_ns"), "subscriber p99 server wait", r.subscriber_p99_server_wait);
    }
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(label + ": " + e.what());
  } catch (const std::runtime_error& e) {
    throw std::runtime_error(label + ": " + e.what());
  }
  return r;
}

LoadResult merge(const std::vector<LoadResult>& runs) {
  if (runs.empty()) throw std::runtime_error("nothing to merge");
  LoadResult m = runs.front();
  m.processes = 0;
  m.clients = m.frames = m.gaps = m.stale = 0;
  m.latency = Histogram{};
  m.server_wait = Histogram{};
  m.subscriber_p99_latency = Histogram{};
  m.subscriber_p99_server_wait = Histogram{};
  m.cpu_user_seconds = m.cpu_system_seconds = 0;
  m.threads = 0;
  m.server_sent = m.server_dropped = m.server_skipped = 0;
  m.have_server = true;
  for (const LoadResult& r : runs) {
    if (r.transport != m.transport || r.shared != m.shared || r.motion != m.motion) {
      throw std::runtime_error("the runs measured different things (motion, transport or sharing differ)");
    }
    m.processes += r.processes;
    m.clients += r.clients;
    m.frames += r.frames;
    m.gaps += r.gaps;
    m.stale += r.stale;
    m.latency.add(r.latency);
    m.server_wait.add(r.server_wait);
    m.subscriber_p99_latency.add(r.subscriber_p99_latency);
    m.subscriber_p99_server_wait.add(r.subscriber_p99_server_wait);
    m.cpu_user_seconds += r.cpu_user_seconds;
    m.cpu_system_seconds += r.cpu_system_seconds;
    m.threads += r.threads;
    m.seconds = std::max(m.seconds, r.seconds);
    m.setup_seconds = std::max(m.setup_seconds, r.setup_seconds);
    m.have_server = m.have_server && r.have_server;
    m.server_sent = std::max(m.server_sent, r.server_sent);
    m.server_dropped = std::max(m.server_dropped, r.server_dropped);
    m.server_skipped = std::max(m.server_skipped, r.server_skipped);
    m.server_computed = std::max(m.server_computed, r.server_computed);
    m.server_encoded = std::max(m.server_encoded, r.server_encoded);
    m.server_late_total = std::max(m.server_late_total, r.server_late_total);
    m.server_io_threads = std::max(m.server_io_threads, r.server_io_threads);
    m.server_multicast_sent = std::max(m.server_multicast_sent, r.server_multicast_sent);
    m.server_cpu_seconds = std::max(m.server_cpu_seconds, r.server_cpu_seconds);
  }
  return m;
}

// ---- text ---------------------------------------------------------------

namespace {

std::string format(const char* fmt, auto... args) {
  char buf[512];
  std::snprintf(buf, sizeof buf, fmt, args...);
  return buf;
}

double ms(double ns) { return ns / 1e6; }

const char* transport_name(const LoadResult& r) {
  return r.transport == "udp" ? "UDP" : r.transport == "multicast" ? "multicast" : "TCP";
}

}  // namespace

std::string describe(const LoadResult& r) {
  const double window = r.seconds > 0 ? r.seconds : 1;
  const double clients = static_cast<double>(std::max<std::uint64_t>(1, r.clients));
  const double expected = r.rate_hz * clients;
  const double got = static_cast<double>(r.frames) / window;
  std::string out;
  out += format("gmr-load: %llu clients%s, motion %s, %s, %.1f Hz each, %s, %.1f s measured\n",
                static_cast<unsigned long long>(r.clients),
                r.processes > 1 ? format(" in %d processes", r.processes).c_str() : "", r.motion.c_str(),
                transport_name(r), r.rate_hz, r.shared ? "one shared stream" : "one stream per client", r.seconds);
  out += format("set-up           %.2f s\n", r.setup_seconds);
  out += format("delivered        %.0f of %.0f frames/s expected (%.2f%%), %.1f/s per client\n", got, expected,
                expected > 0 ? 100.0 * got / expected : 0.0, got / clients);
  const double lost = static_cast<double>(r.gaps);
  out += format(
      "lost             %llu frames never arrived (sequence gaps, %.3f%% of those due)%s\n",
      static_cast<unsigned long long>(r.gaps),
      r.frames + r.gaps > 0 ? 100.0 * lost / static_cast<double>(r.frames + r.gaps) : 0.0,
      r.stale > 0 ? format(", %llu dropped here as stale", static_cast<unsigned long long>(r.stale)).c_str() : "");
  out += format("latency          p50 %.3f ms  p99 %.3f ms  p99.9 %.3f ms  max %.3f ms  (%llu frames)\n",
                ms(r.latency.quantile_ns(0.5)), ms(r.latency.quantile_ns(0.99)), ms(r.latency.quantile_ns(0.999)),
                ms(static_cast<double>(r.latency.max())), static_cast<unsigned long long>(r.latency.count()));
  if (r.server_wait.count() > 0) {
    out += format(
        "  in the server  p50 %.3f ms  p99 %.3f ms  p99.9 %.3f ms  max %.3f ms  (encoded to written: "
        "the fan-out and the I/O thread's queue)\n",
        ms(r.server_wait.quantile_ns(0.5)), ms(r.server_wait.quantile_ns(0.99)), ms(r.server_wait.quantile_ns(0.999)),
        ms(static_cast<double>(r.server_wait.max())));
  }
  if (r.subscriber_p99_latency.count() > 0) {
    auto tail = [](const Histogram& h) {
      return format("median %.3f ms, worst 1%% %.3f ms, worst %.3f ms", ms(h.quantile_ns(0.5)), ms(h.quantile_ns(0.99)),
                    ms(static_cast<double>(h.max())));
    };
    out += format("per subscriber   p99 latency of each subscriber: %s\n", tail(r.subscriber_p99_latency).c_str());
    if (r.subscriber_p99_server_wait.count() > 0) {
      out +=
          format("                 p99 wait in the server of each: %s\n", tail(r.subscriber_p99_server_wait).c_str());
    }
  }
  // The distribution in powers of two of milliseconds, with a bar.
  if (r.latency.count() > 0) {
    out += "histogram        (latency up to; share of frames)\n";
    std::int64_t edge = 125'000;  // 0.125 ms
    std::size_t b = 0;
    std::uint64_t total = r.latency.count(), seen = 0;
    while (seen < total) {
      std::uint64_t in = 0;
      while (b < Histogram::kBuckets && Histogram::bucket_low(b) < edge) in += r.latency.at(b++);
      seen += in;
      const double share = static_cast<double>(in) / static_cast<double>(total);
      const int bar = static_cast<int>(std::lround(share * 50));
      out +=
          format("  %9.3f ms %7.3f%% %s\n", ms(static_cast<double>(edge)), 100 * share, std::string(bar, '#').c_str());
      edge *= 2;
    }
  }
  const double cpu = r.cpu_user_seconds + r.cpu_system_seconds;
  out += format("gmr-load CPU     %.2f cores (%.0f%% of it in the kernel) on %u I/O threads%s\n", cpu / window,
                cpu > 0 ? 100 * r.cpu_system_seconds / cpu : 0.0, r.threads,
                cpu / window > 0.9 * r.threads ? ": the load generator was saturated, not only the server" : "");
  if (r.have_server) {
    out += format(
        "server, window   %llu frames sent to all its clients, %llu dropped (slow reader or full UDP "
        "queue), %llu skipped (late); %llu FK runs, %llu encodings\n",
        static_cast<unsigned long long>(r.server_sent), static_cast<unsigned long long>(r.server_dropped),
        static_cast<unsigned long long>(r.server_skipped), static_cast<unsigned long long>(r.server_computed),
        static_cast<unsigned long long>(r.server_encoded));
  } else {
    out += "server, window   (the server's counters were not available)\n";
  }
  if (r.have_server && r.server_multicast_sent > 0) {
    out += format("multicast        %llu frames sent to the group (once each, for all %llu clients)\n",
                  static_cast<unsigned long long>(r.server_multicast_sent), static_cast<unsigned long long>(r.clients));
  }
  if (r.server_cpu_seconds >= 0) {
    // Multicast: per frame sent to the group (the clients may not be where the group is routed).
    const auto per = r.transport == "multicast" ? r.server_multicast_sent : r.frames;
    out += format("server CPU       %.3f cores, %.0f ns per %s frame%s\n", r.server_cpu_seconds / window,
                  per > 0 ? 1e9 * r.server_cpu_seconds / static_cast<double>(per) : 0.0,
                  r.transport == "multicast" ? "multicast" : "delivered",
                  r.server_io_threads > 0 ? format(", on %u I/O threads", r.server_io_threads).c_str() : "");
  }
  return out;
}

// ---- plot ---------------------------------------------------------------

std::string plot(const LoadResult& r, const std::string& png) {
  if (r.latency.count() == 0) return "no latencies to plot";
  namespace fs = std::filesystem;
  const fs::path data = fs::temp_directory_path() / ("gmr-load-" + std::to_string(::getpid()) + ".dat");
  {
    std::ofstream out(data);
    // Per bucket: its midpoint in ms, the share of frames in it scaled to a
    // bucket 1/32 of an octave wide (buckets are linear within an octave, so
    // on a log axis their widths differ: without the scaling the plot would
    // step at every power of two), and the cumulative share.
    std::uint64_t seen = 0;
    for (std::size_t b = 0; b < Histogram::kBuckets; ++b) {
      if (r.latency.at(b) == 0) continue;
      seen += r.latency.at(b);
      const double lo = static_cast<double>(Histogram::bucket_low(b)) / 1e6;
      const double hi = static_cast<double>(Histogram::bucket_high(b)) / 1e6;
      const double share = static_cast<double>(r.latency.at(b)) / static_cast<double>(r.latency.count());
      out << 0.5 * (lo + hi) << ' ' << share * (std::log(2.0) / 32) / std::log(hi / std::max(lo, 0.5e-6)) << ' '
          << static_cast<double>(seen) / static_cast<double>(r.latency.count()) << '\n';
    }
    if (!out) return "cannot write " + data.string();
  }
  // gnuplot writes beside the target, and the rename makes it whole at once.
  const std::string partial = png + ".partial";
  std::string quoted = "'";
  for (char c : partial) quoted += c == '\'' ? std::string("''") : std::string(1, c);
  quoted += "'";
  const std::string title =
      format("gmr-load: %llu clients, %s%s, %.0f Hz; p50 %.2f ms, p99 %.2f ms, p99.9 %.2f ms",
             static_cast<unsigned long long>(r.clients), transport_name(r), r.shared ? " shared" : "", r.rate_hz,
             ms(r.latency.quantile_ns(0.5)), ms(r.latency.quantile_ns(0.99)), ms(r.latency.quantile_ns(0.999)));
  const std::string script = "set terminal pngcairo size 960,600 font ',11'\nset output " + quoted + "\nset title '" +
                             title +
                             "'\nset logscale x\nset xlabel 'latency (ms)'\n"
                             "set ylabel 'share of frames per 1/32 octave'\nset y2label 'cumulative share'\n"
                             "set y2range [0:1]\nset ytics nomirror\nset y2tics\nset grid\n"
                             "plot '" +
                             data.string() + "' using 1:2 with impulses lw 2 title 'frames', '" + data.string() +
                             "' using 1:3 axes x1y2 with lines lw 2 title 'cumulative'\n";
  FILE* gp = ::popen("gnuplot 2>&1", "w");
  if (gp == nullptr) {
    fs::remove(data);
    return "cannot run gnuplot (apt-get install gnuplot-nox)";
  }
  std::fputs(script.c_str(), gp);
  const int status = ::pclose(gp);
  fs::remove(data);
  std::error_code ec;
  if (status != 0 || !fs::exists(partial, ec)) {
    fs::remove(partial, ec);
    return "gnuplot failed (is it installed? apt-get install gnuplot-nox)";
  }
  fs::rename(partial, png, ec);
  if (ec) return "cannot write " + png + ": " + ec.message();
  return {};
}

}  // namespace gmr::load
