#include "net.h"

#include "gmr/wire/convert.h"

namespace gmr::server {

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Refusal refusal(const Error& error) { return Refusal{wire::error_code_for(error.kind), error.to_string()}; }

pb::ServerMessage error_message(std::uint64_t request_id, pb::ErrorCode code, std::string text) {
  pb::ServerMessage m;
  m.set_request_id(request_id);
  m.mutable_error()->set_code(code);
  m.mutable_error()->set_message(std::move(text));
  return m;
}

}  // namespace gmr::server
