// Services: what a client's session may use of the server, as references to
// the parts the composition root (Server::Impl) owns. Sessions never see the
// root itself, so what a request can touch is written here.
#pragma once

#include <chrono>
#include <memory>
#include <string_view>

#include "admission.h"
#include "catalog.h"
#include "gmr/server/config.h"
#include "live/recordings.h"
#include "live/replicas.h"
#include "streams/stream.h"
#include "streams/stream_registry.h"
#include "streams/targets.h"
#include "transport/io_threads.h"
#include "transport/net.h"
#include "transport/udp_publisher.h"

namespace gmr::server {

// Where a session's requests are counted (the server's metrics).
class RequestObserver {
 public:
  virtual ~RequestObserver() = default;
  // One request answered: its kind (the ClientMessage field's name), how long
  // the server took, and its error code (ERROR_CODE_UNSPECIFIED: none).
  virtual void request(std::string_view kind, Clock::duration took, pb::ErrorCode code) = 0;
  // A message that did not parse as a ClientMessage.
  virtual void unparsable_request() = 0;
};

struct Services {
  const ServerConfig& cfg;
  net::io_context& io;          // the control loop: requests, views and streams
  net::thread_pool& edit_pool;  // long view edits (RequestHandler::edit_view)
  Catalog& catalog;
  Admission& admission;
  StreamRegistry& streams;
  StreamCounters& counters;
  UdpPublisher& udp;
  MulticastGroup& multicast;
  Replicas& replicas;
  Recordings& recordings;
  RequestObserver& observer;
  // The I/O threads, once the server started (null before, and in tests).
  const std::unique_ptr<IoThreads>& lanes;
};

}  // namespace gmr::server
