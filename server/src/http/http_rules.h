// The rules the HTTP port applies to a request before it answers: which
// file a target names, the type it is served as, and whether the request's
// Host and Origin may use the WebSocket and /metrics (docs/security.md).
#pragma once

#include <boost/beast/http.hpp>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>

#include "gmr/server/config.h"

namespace gmr::server {

using HttpRequest = boost::beast::http::request<boost::beast::http::string_body>;

// The Content-Type a file is served with.
std::string_view content_type(const std::filesystem::path& file);

// The part of a request target that names a file under a root: letters,
// digits and . _ - / only, no empty or dot-dot segment. Empty: refused.
std::optional<std::filesystem::path> safe_relative(std::string_view path);

// Why the request's Host is refused (nullopt: it names this server in a way
// no other web site can: an IP address, localhost, this machine's name or a
// name cfg.http_allowed_hosts allows). A page of evil.example whose name was
// made to resolve to this server (DNS rebinding) sends Host: evil.example,
// and its requests pass every same-origin check a browser makes; this is
// what refuses them. No Host at all (HTTP/1.0, a program) is not a
// browser's request.
std::optional<std::string> host_refused(const HttpRequest& req, const ServerConfig& cfg);

// Whether a browser page from the request's Origin may open a WebSocket
// here: a page of this server (same host and port), or one the
// configuration allows. Programs send no Origin. Without this check any web
// site open in a browser on this host could drive a loopback server.
bool origin_allowed(const HttpRequest& req, const ServerConfig& cfg);

}  // namespace gmr::server
