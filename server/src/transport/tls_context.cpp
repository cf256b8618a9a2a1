#include "transport/tls_context.h"

#include <stdexcept>
#include <string>

namespace gmr::server {

std::unique_ptr<net::ssl::context> make_tls_context(const ServerConfig& cfg) {
  if (cfg.tls_certificate_file.empty() && cfg.tls_key_file.empty()) return nullptr;
  if (cfg.tls_certificate_file.empty() || cfg.tls_key_file.empty()) {
    throw std::runtime_error("TLS needs both a certificate (--tls-cert) and its private key (--tls-key)");
  }
  auto ctx = std::make_unique<net::ssl::context>(net::ssl::context::tls_server);
  ctx->set_options(net::ssl::context::default_workarounds | net::ssl::context::no_sslv2 | net::ssl::context::no_sslv3 |
                   net::ssl::context::no_tlsv1 | net::ssl::context::no_tlsv1_1 | net::ssl::context::single_dh_use);
  boost::system::error_code ec;
  ctx->use_certificate_chain_file(cfg.tls_certificate_file, ec);
  if (ec) {
    throw std::runtime_error("cannot use the TLS certificate " + cfg.tls_certificate_file + ": " + ec.message() +
                             " (a PEM certificate chain is expected)");
  }
  ctx->use_private_key_file(cfg.tls_key_file, net::ssl::context::pem, ec);
  if (ec) {
    throw std::runtime_error("cannot use the TLS private key " + cfg.tls_key_file + ": " + ec.message() +
                             " (a PEM private key matching the certificate is expected)");
  }
  return ctx;
}

}  // namespace gmr::server
