// gmr-server: serves a motion library over TCP, UDP and WebSocket (docs/protocol.md),
// with the browser viewer and /metrics on its HTTP port (docs/viewer.md).
//
//   gmr-server [--library DIR] [--port P] [--udp-port U] [--bind ADDR] [limits...]
//
// Startup failures (a bad flag, a port in use, an unreadable library folder)
// exit 1 with one line on stderr. SIGINT/SIGTERM stop gracefully, exit 0.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <functional>

#include "gmr/core/file_util.h"
#include "gmr/server/library.h"
#include "gmr/server/library_watch.h"
#include "gmr/server/server.h"

namespace {

// The viewer's files: installed beside the program (PREFIX/share/gmr/web),
// or, in a build tree, the source tree's.
std::string default_web_root() {
  std::error_code ec;
  const auto exe = std::filesystem::canonical("/proc/self/exe", ec);
  if (!ec) {
    const auto installed = exe.parent_path().parent_path() / "share" / "gmr" / "web";
    if (std::filesystem::is_regular_file(installed / "index.html", ec)) return installed.string();
  }
  return GMR_SOURCE_WEB_ROOT;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace gmr::server;
  CLI::App app{
      "gmr-server: streams GMR motions over TCP, UDP and WebSocket, with a browser viewer and /metrics on HTTP"};
  ServerConfig cfg;
  cfg.port = 7400;  // the port the gmr command, gmr-load and docker/ expect by default
  std::string library_dir;
  std::string log_level = "info";
  std::string port_file;
  unsigned threads = 0;
  long long idle_ms = cfg.idle_timeout.count();
  long long heartbeat_ms = cfg.heartbeat_interval.count();
  long long write_ms = cfg.write_timeout.count();
  long long congested_ms = cfg.congested_after.count();
  long long handshake_ms = cfg.handshake_timeout.count();
  double tick_grid_ms = std::chrono::duration<double, std::milli>(cfg.tick_grid).count();
  app.add_option("--library", library_dir,
                 "Folder of BVH, ASF/AMC and GMR files (default: the built-in demo library); watched while running: "
                 "files added, replaced or removed are picked up, and SIGHUP reads it again (docs/protocol.md, "
                 "\"Library reload\")");
  app.add_option("--port", cfg.port, "TCP port (0: any free port)")->capture_default_str();
  app.add_option("--udp-port", cfg.udp_port,
                 "UDP port (default: the TCP port number, or any free port with --port 0; 0: any free port)");
  app.add_option("--bind", cfg.bind_address, "Address to listen on (loopback unless told otherwise)")
      ->capture_default_str();
  app.add_option("--max-message-bytes", cfg.max_message_bytes, "Largest message either way")->capture_default_str();
  app.add_option("--max-connections", cfg.max_connections, "Connections served at once")->capture_default_str();
  app.add_option("--io-threads", cfg.io_threads,
                 "Threads that send frames and read requests; connections are spread over them, one of them also "
                 "runs requests and streams (0: one per CPU)")
      ->capture_default_str()
      ->check(CLI::Range(std::size_t{0}, std::size_t{64}));
  app.add_option("--max-views", cfg.max_views_per_connection, "Views per connection")->capture_default_str();
  app.add_option("--max-connections-per-address", cfg.max_connections_per_address,
                 "Connections from one IP address (0: no limit; load tests on one host need 0)")
      ->capture_default_str();
  app.add_option("--max-pending-handshakes", cfg.max_pending_handshakes,
                 "Connections waiting for their Hello at once (a new one pushes out the oldest)")
      ->capture_default_str();
  app.add_option("--handshake-timeout-ms", handshake_ms, "Close a connection that has not said Hello by then")
      ->capture_default_str();
  app.add_option("--max-subscriptions", cfg.max_subscriptions_per_connection, "Subscriptions per connection")
      ->capture_default_str();
  app.add_option("--frames-per-subscription", cfg.frames_per_subscription,
                 "Frames queued per subscription before the oldest is dropped (latest wins)")
      ->capture_default_str();
  // Memory (docs/protocol.md, "Memory budget").
  MotionLimits motion_limits;
  gmr::LoadOptions library_files;
  double library_unit = 0.0;
  app.add_option("--metres-per-unit", library_unit,
                 "The unit of the library's files in metres (0.0254: inches), for clients' engine conventions, "
                 "for files that declare none (an .amc takes its .asf's, a BVH or .gmr its X.units or folder.units "
                 "sidecar's; default: unknown; the built-in demo is in centimetres)")
      ->check(CLI::PositiveNumber);
  app.add_option("--amc-fps", library_files.amc_fps,
                 "Frames per second of the library's .amc files, which do not say (default 120, the CMU captures')")
      ->check(CLI::PositiveNumber);
  app.add_option("--max-motion-joint-frames", motion_limits.max_joint_frames,
                 "Largest motion served, frames x joints (larger files are rejected at load)")
      ->capture_default_str();
  app.add_option("--max-motion-bytes", motion_limits.max_value_bytes,
                 "Largest motion served, bytes of channel values (larger files are rejected at load)")
      ->capture_default_str();
  app.add_option("--max-reply-queue-bytes", cfg.max_reply_queue_bytes,
                 "Replies held per connection before its requests wait")
      ->capture_default_str();
  app.add_option("--max-frame-bytes", cfg.max_frame_bytes_per_connection,
                 "Frames waiting per connection, all subscriptions (the oldest give way)")
      ->capture_default_str();
  app.add_option("--max-buffered-bytes", cfg.max_buffered_bytes,
                 "Bytes all connections may hold together (0: no server-wide limit)")
      ->capture_default_str();
  std::size_t fk_cache_mb = cfg.fk_cache_bytes >> 20;
  app.add_option("--fk-cache-mb", fk_cache_mb,
                 "MiB of forward kinematics kept for streams to share, computed 16 frames at a time (0: none kept, "
                 "each stream's frame computed on its own)")
      ->capture_default_str()
      ->check(CLI::Range(std::size_t{0}, std::size_t{1} << 20));
  std::string send_budget = "auto";
  app.add_option("--send-budget", send_budget,
                 "Frames/s all subscriptions together may ask for; past it a subscription is refused. auto: "
                 "measured at start (about 0.5 s) and again over the first minute; 0: no limit, for load tests that "
                 "mean to overload")
      ->capture_default_str()
      ->check([](const std::string& v) -> std::string {
        double x = 0;
        const auto [end, ec] = std::from_chars(v.data(), v.data() + v.size(), x);
        if (v == "auto" || (ec == std::errc() && end == v.data() + v.size() && x >= 0 && std::isfinite(x))) return {};
        return "--send-budget takes auto or a number of frames per second (0: no limit), not '" + v + "'";
      });
  app.add_option("--max-view-bytes", cfg.max_view_bytes, "Motion bytes all edited views may own together")
      ->capture_default_str();
  app.add_option("--max-view-bytes-per-connection", cfg.max_view_bytes_per_connection,
                 "Motion bytes one connection's edited views may own")
      ->capture_default_str();
  app.add_option("--socket-unsent-bytes", cfg.socket_unsent_bytes,
                 "TCP_NOTSENT_LOWAT per connection: bytes the kernel may hold unsent before frames wait in the "
                 "server's queue, where stale ones are dropped (0: the system's setting)");
  app.add_option("--socket-send-buffer", cfg.socket_send_buffer,
                 "SO_SNDBUF per connection in bytes (0: the kernel's autotuning)")
      ->capture_default_str();
  app.add_option("--idle-timeout-ms", idle_ms, "Close a connection silent for this long")->capture_default_str();
  app.add_option("--heartbeat-ms", heartbeat_ms, "Send a heartbeat after this long without writing")
      ->capture_default_str();
  app.add_option("--write-timeout-ms", write_ms, "Close a connection whose write stalls this long")
      ->capture_default_str();
  app.add_option("--congested-after-ms", congested_ms,
                 "Compute no frames for a subscription whose frames have waited this long behind a stalled write "
                 "(or UDP lane)")
      ->capture_default_str();
  app.add_option("--tick-grid-ms", tick_grid_ms,
                 "Own streams start on points of their period this far apart, taken in turn, so streams of one rate "
                 "tick in a few evenly filled groups; a start waits at most 10 ms (0: each from the moment it starts)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1000.0));
  app.add_option("--load-threads", threads, "Threads loading the library (0: one per core)");
  std::string auth_file, anonymous;
  app.add_option("--auth-file", auth_file,
                 "Tokens and their roles, one 'read TOKEN', 'control TOKEN' or 'publish TOKEN' per line "
                 "(docs/security.md)")
      ->check(CLI::ExistingFile);
  app.add_option("--anonymous-share", cfg.anonymous_share,
                 "With --auth-file: the part of --max-connections clients without a token may hold (1: no bound)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  app.add_option("--anonymous", anonymous,
                 "What clients without a token may do: none, read, control or publish (default: read with "
                 "--auth-file, control without; publishing live sources needs a 'publish' token or this)")
      ->check(CLI::IsMember({"none", "read", "control", "publish"}));
  app.add_option("--record-dir", cfg.record_dir,
                 "Write live sources that ask to be recorded here, as .gmrb, when they end")
      ->check(CLI::ExistingDirectory);
  app.add_option("--max-record-bytes", cfg.max_record_bytes,
                 "Values one recording may hold; past them it stops growing")
      ->capture_default_str();
  app.add_option("--max-record-total-bytes", cfg.max_record_total_bytes,
                 "Bytes all recordings under way may hold together; past them they stop growing and new ones are "
                 "refused")
      ->capture_default_str();
  app.add_option("--max-record-dir-bytes", cfg.max_record_dir_bytes,
                 "Bytes the record directory may hold, its files and the recordings under way (0: no bound; 256 MiB "
                 "of the disk always stay free)")
      ->capture_default_str();
  app.add_option("--multicast-group", cfg.multicast_group,
                 "IPv4 multicast group (239.255.74.1) for shared streams subscribed over multicast (default: none)");
  app.add_option("--multicast-port", cfg.multicast_port, "Port of the multicast group")->capture_default_str();
  app.add_option("--multicast-ttl", cfg.multicast_ttl, "Hops multicast frames may take (1: this network segment)")
      ->capture_default_str()
      ->check(CLI::Range(0, 255));
  app.add_option("--discovery-group", cfg.discovery_group,
                 "Send a discovery beacon (gmr discover) to this IPv4 multicast group every second (default: none; "
                 "239.255.74.2 is gmr discover's)");
  app.add_option("--discovery-port", cfg.discovery_port, "Port of the discovery group")->capture_default_str();
  app.add_option("--nats", cfg.nats_url,
                 "A NATS server (nats://host:4222) through which replicas share live sources (docs/deployment.md)");
  app.add_option("--nats-subject", cfg.nats_subject, "The NATS subject of live sources")->capture_default_str();
  app.add_option("--nats-creds", cfg.nats_credentials_file,
                 "NATS credentials: a .creds file (JWT and seed), or lines 'user NAME' + 'password PASS', "
                 "'token TOKEN', or 'nkey PUBLIC' + 'seed SEED' (docs/deployment.md)")
      ->check(CLI::ExistingFile);
  std::string relay_secret_file;
  app.add_option("--relay-secret-file", relay_secret_file,
                 "A secret every replica shares (at least 32 characters): relay messages are authenticated with "
                 "HMAC-SHA256 under it, and others refused (docs/deployment.md)")
      ->check(CLI::ExistingFile);
  int relay_timeout_ms = static_cast<int>(cfg.relay_timeout.count());
  app.add_option("--relay-timeout-ms", relay_timeout_ms,
                 "End another replica's live source after this long without word from it")
      ->capture_default_str()
      ->check(CLI::Range(100, 3600000));
  app.add_option("--max-remote-sources", cfg.max_remote_sources,
                 "Serve at most this many live sources of other replicas (the rest are refused and counted)")
      ->capture_default_str()
      ->check(CLI::Range(std::size_t{0}, std::size_t{1} << 20));
  app.add_option("--tls-cert", cfg.tls_certificate_file, "PEM certificate chain: the TCP port then speaks only TLS")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-key", cfg.tls_key_file, "PEM private key of --tls-cert")->check(CLI::ExistingFile);
  app.add_option("--port-file", port_file, "Write the TCP port here once listening (for scripts using --port 0)");
  int http_port = -1;
  std::string http_port_file;
  auto* http_port_option = app.add_option(
      "--http-port", http_port,
      "HTTP port for the browser viewer, its WebSocket, /metrics, /healthz and /readyz (default 7480, or any free "
      "port with --port 0; -1: no HTTP)");
  app.add_option("--http-port-file", http_port_file, "Write the HTTP port here once listening");
  app.add_option("--web-root", cfg.web_root,
                 "The viewer's files (default: the installed share/gmr/web, or the source tree's server/web)");
  app.add_option("--three-dir", cfg.three_dir, "Where three.js is (Debian's libjs-three)")->capture_default_str();
  app.add_option("--allow-origin", cfg.http_allowed_origins,
                 "An origin (http://host:port, or *) besides the server's own whose pages may open the WebSocket; "
                 "repeatable");
  app.add_option("--max-http-sessions", cfg.max_http_sessions,
                 "HTTP connections open at once (WebSockets count "
                 "under --max-connections)")
      ->capture_default_str();
  app.add_option("--max-http-sessions-per-address", cfg.max_http_sessions_per_address,
                 "HTTP connections one address (IPv6: its /64) may hold")
      ->capture_default_str();
  app.add_option("--allow-host", cfg.http_allowed_hosts,
                 "A host name (as browsers send it in Host, without the port) the WebSocket and /metrics answer "
                 "to, besides IP addresses and localhost; repeatable (docs/security.md, DNS rebinding)");
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error")->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  const bool http_port_given = http_port_option->count() > 0;
  spdlog::set_level(spdlog::level::from_str(log_level));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%e %^%l%$ %v");
  if (idle_ms <= 0 || heartbeat_ms <= 0 || write_ms <= 0 || handshake_ms <= 0 || congested_ms <= 0) {
    std::fprintf(stderr, "gmr-server: timeouts must be positive\n");
    return 1;
  }
  if (cfg.max_message_bytes < 4096 || cfg.max_connections == 0 || cfg.max_views_per_connection == 0 ||
      cfg.max_subscriptions_per_connection == 0 || cfg.frames_per_subscription == 0 ||
      cfg.max_pending_handshakes == 0 || cfg.max_http_sessions == 0) {
    std::fprintf(stderr, "gmr-server: --max-message-bytes must be at least 4096 and the other limits at least 1\n");
    return 1;
  }
  cfg.calibrate_send_budget = send_budget == "auto";
  if (!cfg.calibrate_send_budget) cfg.send_budget = std::strtod(send_budget.c_str(), nullptr);
  cfg.fk_cache_bytes = fk_cache_mb << 20;
  cfg.idle_timeout = std::chrono::milliseconds(idle_ms);
  cfg.relay_timeout = std::chrono::milliseconds(relay_timeout_ms);
  cfg.heartbeat_interval = std::chrono::milliseconds(heartbeat_ms);
  cfg.write_timeout = std::chrono::milliseconds(write_ms);
  cfg.congested_after = std::chrono::milliseconds(congested_ms);
  cfg.handshake_timeout = std::chrono::milliseconds(handshake_ms);
  cfg.tick_grid = std::chrono::microseconds(std::llround(tick_grid_ms * 1000.0));

  // The auth file, at start and on SIGHUP; a readable-by-others warning is logged.
  auto read_credentials = [&auth_file]() -> gmr::Result<std::shared_ptr<const Credentials>> {
    std::string warning;
    auto credentials = Credentials::load(auth_file, &warning);
    if (!credentials.ok()) return credentials.error();
    if (!warning.empty()) spdlog::warn("{}", warning);
    return std::make_shared<const Credentials>(std::move(credentials).value());
  };
  if (!auth_file.empty()) {
    auto credentials = read_credentials();
    if (!credentials.ok()) {
      std::fprintf(stderr, "gmr-server: %s\n", credentials.error().to_string().c_str());
      return 1;
    }
    cfg.credentials = std::move(credentials).value();
    cfg.anonymous = Role::kRead;
  }
  if (!anonymous.empty()) cfg.anonymous = parse_role(anonymous).value();
  if (!relay_secret_file.empty()) {
    auto secret = gmr::server::read_relay_secret(relay_secret_file);
    if (!secret.ok()) {
      std::fprintf(stderr, "gmr-server: %s\n", secret.error().to_string().c_str());
      return 1;
    }
    cfg.relay_secret = std::move(secret).value();
  }

  if (http_port < -1 || http_port > 65535) {
    std::fprintf(stderr, "gmr-server: --http-port must be -1 (no HTTP) or a port number\n");
    return 1;
  }
  // HTTP on its own port: 7480 beside the default TCP port, any free port
  // beside --port 0 (as UDP), unless told.
  cfg.http_port = http_port_given ? http_port : cfg.port == 0 ? 0 : 7480;
  if (cfg.web_root.empty()) cfg.web_root = default_web_root();

  try {
    // Listening first, then loading: /healthz answers and /readyz says
    // "loading" meanwhile; TCP clients wait in the backlog until it is done.
    Server server(cfg);
    server.start();
    if (!port_file.empty()) {
      if (auto s = gmr::write_file_atomic(port_file, std::to_string(server.tcp_port()) + "\n"); !s.ok()) {
        throw std::runtime_error(s.error().to_string());
      }
    }
    if (!http_port_file.empty()) {
      if (auto s = gmr::write_file_atomic(http_port_file, std::to_string(server.http_port()) + "\n"); !s.ok()) {
        throw std::runtime_error(s.error().to_string());
      }
    }
    if (server.http_port() != 0) {
      spdlog::info("viewer: http://{}:{}/ (files from {})   metrics: /metrics   health: /healthz /readyz",
                   cfg.bind_address == "0.0.0.0" ? std::string("127.0.0.1") : cfg.bind_address, server.http_port(),
                   cfg.web_root);
    }
    std::vector<LibraryEntry> library;
    if (library_dir.empty()) {
      library = builtin_library();
      spdlog::info("built-in demo library: {} motions", library.size());
    } else {
      spdlog::info("loading {}", library_dir);
      auto loaded = load_library(
          library_dir, threads,
          [](std::size_t done, std::size_t total, const std::filesystem::path& file, const std::string* why) {
            // Rejections are listed once, sorted, when loading is done.
            if (!why) spdlog::debug("loaded {}", file.string());
            if (done == total || done % 10 == 0) spdlog::info("loading: {}/{} files", done, total);
          },
          motion_limits, library_files);
      if (!loaded.ok()) {
        server.stop();
        std::fprintf(stderr, "gmr-server: %s\n", loaded.error().to_string().c_str());
        return 1;
      }
      for (const auto& r : loaded->rejected) spdlog::warn("rejected {}: {}", r.path.string(), r.reason);
      spdlog::info("library: {} motions loaded, {} files rejected, {} other files skipped", loaded->entries.size(),
                   loaded->rejected.size(), loaded->skipped);
      library = std::move(loaded->entries);
      // A file's own unit (an ASF or a sidecar declares one) comes first;
      // --metres-per-unit covers the files that declare none.
      std::size_t unknown = 0;
      for (auto& e : library) {
        if (e.metres_per_unit == 0.0) e.metres_per_unit = library_unit;
        if (e.metres_per_unit == 0.0) ++unknown;
      }
      if (unknown > 0) {
        spdlog::warn(
            "library: {} of {} motions have no known unit (a BVH or .gmr declares none): engine conventions "
            "leave their numbers in the file's units; declare it in X.units or folder.units beside them, or "
            "give --metres-per-unit (docs/protocol.md, \"Units\")",
            unknown, library.size());
      }
    }
    const std::vector<LibraryEntry> served = library;
    server.set_library(std::move(library));
    // The folder is watched from now on: files added, replaced or removed
    // are served, read again or dropped while running (docs/protocol.md,
    // "Library reload"); SIGHUP reads it again too.
    std::unique_ptr<gmr::server::LibraryWatcher> watcher;
    if (!library_dir.empty()) {
      gmr::server::LibraryWatcher::Options watch;
      watch.dir = library_dir;
      watch.threads = threads;
      watch.limits = motion_limits;
      watch.file_options = library_files;
      watch.default_metres_per_unit = library_unit;
      watcher = std::make_unique<gmr::server::LibraryWatcher>(server, watch, served);
    }
    // The main thread waits for a signal; the server runs on its own thread.
    // SIGHUP reads the auth file again (a file that does not parse leaves
    // the tokens in use as they are) and the library folder.
    boost::asio::io_context signals_io;
    boost::asio::signal_set signals(signals_io, SIGINT, SIGTERM, SIGHUP);
    std::function<void(const boost::system::error_code&, int)> on_signal = [&](const boost::system::error_code& ec,
                                                                               int sig) {
      if (ec) return;
      if (sig != SIGHUP) {
        spdlog::info("signal {}: stopping", sig);
        return;
      }
      if (watcher) {
        spdlog::info("SIGHUP: reading {} again", library_dir);
        watcher->reload();
      }
      if (auth_file.empty()) {
        spdlog::info("SIGHUP: no --auth-file to read again");
      } else {
        auto credentials = read_credentials();
        if (!credentials.ok()) {
          spdlog::error("SIGHUP: the tokens in use stay: {}", credentials.error().to_string());
        } else {
          spdlog::info("SIGHUP: {} tokens read from {}", (*credentials)->size(), auth_file);
          server.set_credentials(std::move(credentials).value());
        }
      }
      signals.async_wait(on_signal);
    };
    signals.async_wait(on_signal);
    signals_io.run();
    server.stop();
    spdlog::info("stopped");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gmr-server: %s\n", e.what());
    return 1;
  }
  return 0;
}
