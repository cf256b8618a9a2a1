// What a server or client reads from the network: the first byte picks the
// decoder (length prefix, ClientMessage, ServerMessage and its frames and
// skeletons, UDP registration, UDP fragments), the rest is its input. Any
// bytes give a value or an error, never a crash or unbounded memory; and a
// frame the client reads in place holds what protobuf parses from it.
#include <array>
#include <cstdint>
#include <cstdlib>
#include <span>
#include <string>

#include "gmr/stream/v1/stream.pb.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/frames.h"
#include "gmr/wire/framing.h"
#include "gmr/wire/udp.h"

namespace pb = gmr::stream::v1;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const std::string body(reinterpret_cast<const char*>(data + 1), size - 1);
  switch (data[0] % 5) {
    case 0: {  // length prefixes, one after another
      for (std::size_t i = 0; i + 4 <= body.size(); i += 4) {
        std::array<std::uint8_t, 4> prefix;
        for (std::size_t k = 0; k < 4; ++k) prefix[k] = static_cast<std::uint8_t>(body[i + k]);
        (void)gmr::wire::check_length(gmr::wire::read_length_prefix(prefix), gmr::wire::kDefaultMaxMessageBytes);
      }
      break;
    }
    case 1: {  // a request as the server parses it
      pb::ClientMessage m;
      (void)m.ParseFromString(body);
      break;
    }
    case 2: {  // a reply as the client decodes it
      // A frame read in place must be the frame protobuf parses (checked: a
      // difference aborts).
      gmr::wire::FrameFields fields;
      const bool read = gmr::wire::read_frame_message(body, fields);
      pb::ServerMessage m;
      if (!m.ParseFromString(body)) {
        if (read) std::abort();
        break;
      }
      if (read) {
        if (!m.has_frame()) std::abort();
        gmr::wire::FrameValues in_place;
        const gmr::Status s = gmr::wire::unpack_frame(fields, in_place);
        const auto parsed = gmr::wire::decode_frame(m.frame());
        if (s.ok() != parsed.ok()) std::abort();
        if (s.ok() && !gmr::wire::same_bits(in_place, *parsed)) std::abort();
      }
      if (m.has_frame()) (void)gmr::wire::decode_frame(m.frame());
      if (m.has_frames()) (void)gmr::wire::decode_block(m.frames());
      if (m.has_view()) (void)gmr::wire::from_proto(m.view().skeleton());
      if (m.has_skeleton()) (void)gmr::wire::from_proto(m.skeleton().skeleton());
      break;
    }
    case 3:
      (void)gmr::wire::parse_register_datagram(body);
      break;
    case 4: {  // datagrams: each one a length byte, then that many bytes
      gmr::wire::Reassembler r;
      for (std::size_t i = 0; i < body.size();) {
        const std::size_t n = static_cast<std::uint8_t>(body[i]) * 8u;
        const std::size_t take = std::min(n, body.size() - i - 1);
        if (auto msg = r.add(std::string_view(body).substr(i + 1, take))) {
          pb::ServerMessage m;
          (void)m.ParseFromString(*msg);
        }
        i += 1 + take;
      }
      break;
    }
  }
  return 0;
}
