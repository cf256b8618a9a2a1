// The server's parts without its sockets, for driving a RequestHandler (or
// the replicas' relay handling) directly: what Server::Impl owns, put
// together the same way, and the Services a session is given. Used by
// request_handler_test.cpp and fuzz/requests_fuzz.cpp.
#pragma once

#include <memory>
#include <utility>
#include <vector>

#include "admission.h"
#include "catalog.h"
#include "http/metrics.h"
#include "live/recordings.h"
#include "live/replicas.h"
#include "requests/services.h"
#include "streams/fk_blocks.h"
#include "streams/stream_registry.h"
#include "streams/targets.h"
#include "transport/io_threads.h"
#include "transport/udp_publisher.h"

namespace gmr::test {

struct ServerParts {
  ServerParts(server::ServerConfig config, std::vector<server::LibraryEntry> library)
      : cfg(std::move(config)), catalog(std::move(library)) {}

  server::ServerConfig cfg;
  server::Catalog catalog;
  server::Metrics metrics;
  server::Recordings recordings{cfg};
  server::Admission admission{cfg};
  std::unique_ptr<server::IoThreads> lanes;  // none: everything on io
  server::net::io_context io;
  server::UdpPublisher udp{io, cfg.max_udp_datagrams_in_flight};
  server::MulticastGroup multicast;
  server::FkBlocks fk_blocks{cfg.fk_cache_bytes};
  server::StreamCounters counters{.tick_lateness = &metrics.tick_lateness(), .fk_blocks = &fk_blocks};
  server::StreamRegistry streams{io, counters, cfg.tick_grid};
  server::Replicas replicas{io, cfg, catalog};
  server::net::thread_pool edit_pool{1};
  server::Services services{cfg, io,        edit_pool, catalog,    admission, streams, counters,
                            udp, multicast, replicas,  recordings, metrics,   lanes};
};

}  // namespace gmr::test
