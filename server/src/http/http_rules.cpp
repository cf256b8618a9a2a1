#include "http/http_rules.h"

#include <unistd.h>

#include <array>
#include <boost/asio/ip/address.hpp>
#include <cctype>

namespace gmr::server {

namespace http = boost::beast::http;
namespace net = boost::asio;

std::string_view content_type(const std::filesystem::path& file) {
  const std::string ext = file.extension().string();
  if (ext == ".html") return "text/html; charset=utf-8";
  if (ext == ".js" || ext == ".mjs") return "text/javascript; charset=utf-8";
  if (ext == ".css") return "text/css; charset=utf-8";
  if (ext == ".json" || ext == ".map") return "application/json";
  if (ext == ".png") return "image/png";
  if (ext == ".svg") return "image/svg+xml";
  if (ext == ".ico") return "image/x-icon";
  return "application/octet-stream";
}

std::optional<std::filesystem::path> safe_relative(std::string_view path) {
  if (path.empty() || path.size() > 512) return std::nullopt;
  for (const char c : path) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
                    c == '_' || c == '-' || c == '/';
    if (!ok) return std::nullopt;
  }
  std::filesystem::path rel;
  std::size_t start = 0;
  while (start <= path.size()) {
    const std::size_t slash = std::min(path.find('/', start), path.size());
    const std::string_view segment = path.substr(start, slash - start);
    if (segment.empty() || segment == "." || segment == "..") return std::nullopt;
    rel /= std::string(segment);
    start = slash + 1;
  }
  return rel;
}

std::optional<std::string> host_refused(const HttpRequest& req, const ServerConfig& cfg) {
  const auto field = req[http::field::host];
  std::string_view host(field.data(), field.size());
  if (host.empty()) return std::nullopt;
  // Without the port: [v6]:port, name:port, v4:port.
  std::string_view name = host;
  if (name.front() == '[') {
    const auto close = name.find(']');
    name = close == std::string_view::npos ? std::string_view() : name.substr(1, close - 1);
  } else if (const auto colon = name.rfind(':'); colon != std::string_view::npos) {
    name = name.substr(0, colon);
  }
  auto lower = [](std::string_view s) {
    std::string out(s);
    for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return out;
  };
  const std::string n = lower(name);
  boost::system::error_code ec;
  (void)net::ip::make_address(n, ec);
  if (!n.empty() && (!ec || n == "localhost" || n.ends_with(".localhost"))) return std::nullopt;
  for (const auto& allowed : cfg.http_allowed_hosts) {
    if (lower(allowed) == n) return std::nullopt;
  }
  // This machine's own name (a browser on the LAN that asks for it by name).
  static const std::string own = [&] {
    std::array<char, 256> buf{};
    return ::gethostname(buf.data(), buf.size() - 1) == 0 ? lower(buf.data()) : std::string();
  }();
  if (!own.empty() && (n == own || n == own + ".local")) return std::nullopt;
  return "Host '" + lower(host.substr(0, 100)) +
         "' is not an address or a name of this server (--allow-host; docs/security.md, DNS rebinding)";
}

bool origin_allowed(const HttpRequest& req, const ServerConfig& cfg) {
  const auto origin = req[http::field::origin];
  if (origin.empty()) return true;
  const std::string_view o(origin.data(), origin.size());
  const auto host = req[http::field::host];
  const std::string_view h(host.data(), host.size());
  if (!h.empty() && (o == "http://" + std::string(h) || o == "https://" + std::string(h))) return true;
  for (const auto& allowed : cfg.http_allowed_origins) {
    if (allowed == "*" || allowed == o) return true;
  }
  return false;
}

}  // namespace gmr::server
