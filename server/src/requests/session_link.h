// SessionLink: what the request families of one client's session share
// (views.h, subscriptions.h, publications.h, and the session itself,
// request_handler.h): the server's Services, the connection their answers
// and pushes go to, and the connection's id for the log. Also the small
// rules every family applies the same way.
#pragma once

#include <cstdint>
#include <memory>

#include "gmr/view/conventions.h"
#include "requests/services.h"
#include "transport/outbox.h"

namespace gmr::server {

class SessionLink {
 public:
  SessionLink(Services& parts, const std::shared_ptr<Outbox>& outbox)
      : services(parts), connection_id(outbox->id()), connection_(outbox) {}

  Services& services;
  const std::uint64_t connection_id;
  // Motion bytes this session's views (edited copies) and live sources
  // (skeleton and newest frame) own, against max_view_bytes_per_connection;
  // also counted in Admission::view_bytes, against max_view_bytes.
  std::uint64_t held_bytes = 0;

  // The connection, while it is there.
  std::shared_ptr<Outbox> connection() const { return connection_.lock(); }
  // `m`, framed, to the connection (a message too large to send becomes an
  // INTERNAL error reply saying so); nothing once it stopped.
  void send(const pb::ServerMessage& m) const;

 private:
  std::weak_ptr<Outbox> connection_;
};

// The output basis a request's conventions ask for (docs/protocol.md,
// "Conventions"): an error message for unknown presets or bad axes/units.
// motion_metres_per_unit: the library's word on the motion's unit (0: unknown),
// used when the request gives none.
Result<OutputBasis> output_basis_of(const pb::Conventions& c, double motion_metres_per_unit);
// A library error as the protocol's: NOT_FOUND for an unknown joint,
// RESOURCE_EXHAUSTED for memory, FAILED_PRECONDITION for anything else the
// view refuses (the view is left as it was).
Refusal refusal_of(const Error& e);
Refusal unknown_view(std::uint32_t id);
// An empty answer: the request was done.
pb::ServerMessage ack();

}  // namespace gmr::server
