// The WebSocket's JSON format ("gmr.stream.v1.json", docs/protocol.md):
// protobuf's canonical JSON mapping of the protocol's messages, for pages
// that have no protobuf runtime.
#pragma once

#include <string>
#include <string_view>

#include "gmr/core/error.h"
#include "transport/net.h"

namespace gmr::server {

// protobuf's JSON mapping of a ServerMessage carrying a Frame, written
// directly: MessageToJsonString takes 69 us for a 38-joint float64 frame,
// parsing it and this 4.6 us (bench/wire_bench.cpp). Parsed back with
// JsonStringToMessage it gives `m` again, every Frame field included
// (tests/net/http/server_http_test.cpp checks each one).
std::string frame_to_json(const pb::ServerMessage& m);

// A ServerMessage's bytes as its JSON (a frame through frame_to_json).
Result<std::string> server_message_to_json(std::string_view body);
// A ClientMessage's JSON as its bytes, or why the text is not one.
Result<std::string> client_message_from_json(const std::string& text);

}  // namespace gmr::server
