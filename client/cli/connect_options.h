// The options of every command that talks to a server (gmr ls/skeleton/
// query/stream and gmr-load): where it is, and how to reach it safely.
#pragma once

#include <CLI/CLI.hpp>
#include <chrono>
#include <string>

#include "gmr/client/client.h"

namespace gmr::cli {

// The options, bound to `o`; each default is what `o` holds when added.
inline void add_connect_options(CLI::App& cmd, client::ClientOptions& o) {
  cmd.add_option("--host", o.host, "Server address")->capture_default_str();
  cmd.add_option_function<int>(
         "--timeout-ms", [&o](int ms) { o.timeout = std::chrono::milliseconds(ms); },
         "How long to wait to connect and for each reply (default " + std::to_string(o.timeout.count()) + ")")
      ->check(CLI::Range(100, 600000));
  cmd.add_option("--port", o.port, "Server TCP port")->capture_default_str();
  cmd.add_option("--token", o.auth_token, "Token from the server's auth file (docs/security.md)")->envname("GMR_TOKEN");
  cmd.add_flag("--tls", o.tls.enabled, "Speak TLS; the server's certificate must chain to the system's trust store");
  cmd.add_option("--tls-ca", o.tls.ca_file, "PEM file of the CA (or self-signed certificate) to trust (implies --tls)")
      ->check(CLI::ExistingFile)
      ->each([&o](const std::string&) { o.tls.enabled = true; });
  cmd.add_option("--tls-server-name", o.tls.server_name,
                 "Name the server's certificate must carry (default: --host; implies --tls)")
      ->each([&o](const std::string&) { o.tls.enabled = true; });
}

}  // namespace gmr::cli
