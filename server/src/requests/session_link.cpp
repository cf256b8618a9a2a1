#include "requests/session_link.h"

#include <string>

#include "gmr/wire/framing.h"

namespace gmr::server {

static_assert(static_cast<int>(pb::CONVENTION_PRESET_CUSTOM) == static_cast<int>(ConventionPreset::kCustom) &&
              static_cast<int>(pb::CONVENTION_PRESET_GODOT) == static_cast<int>(ConventionPreset::kGodot));

void SessionLink::send(const pb::ServerMessage& m) const {
  auto c = connection_.lock();
  if (!c || c->stopped()) return;
  auto bytes = wire::frame_message(m, services.cfg.max_message_bytes);
  if (!bytes.ok()) {
    bytes = wire::frame_message(
        error_message(m.request_id(), pb::ERROR_CODE_INTERNAL, "reply too large: " + bytes.error().message));
  }
  c->send(std::move(bytes).value());
}

Result<OutputBasis> output_basis_of(const pb::Conventions& c, double motion_metres_per_unit) {
  // proto3 keeps enum values it does not know: refuse them rather than guess.
  if (!pb::ConventionPreset_IsValid(c.preset())) {
    return make_error("unknown conventions preset " + std::to_string(c.preset()));
  }
  Conventions g;
  g.preset = static_cast<ConventionPreset>(c.preset());
  g.up = c.up();
  g.forward = c.forward();
  g.left_handed = c.left_handed();
  g.target_metres_per_unit = c.target_metres_per_unit() == 0.0 ? 1.0 : c.target_metres_per_unit();
  // The request's word on the motion's unit, else the library's.
  g.source_metres_per_unit = c.source_metres_per_unit() != 0.0 ? c.source_metres_per_unit() : motion_metres_per_unit;
  return output_basis(g);
}

Refusal refusal_of(const Error& e) {
  switch (e.kind) {
    case ErrorKind::kNotFound:
      return Refusal{pb::ERROR_CODE_NOT_FOUND, e.to_string()};
    case ErrorKind::kResourceExhausted:
      return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, e.to_string()};
    default:
      return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, e.to_string()};
  }
}

Refusal unknown_view(std::uint32_t id) {
  return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown view " + std::to_string(id)};
}

pb::ServerMessage ack() {
  pb::ServerMessage out;
  out.mutable_ack();
  return out;
}

}  // namespace gmr::server
