// The TLS context client connections share: the server's certificate and key.
#pragma once

#include <memory>

#include "gmr/server/config.h"
#include "transport/net.h"

namespace gmr::server {

// TLS 1.2 or newer with cfg's certificate chain and private key (PEM); null
// when cfg names neither. Throws std::runtime_error naming the file and the
// reason when one is missing or unusable.
std::unique_ptr<net::ssl::context> make_tls_context(const ServerConfig& cfg);

}  // namespace gmr::server
