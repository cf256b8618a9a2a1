#include "transport/ws_json.h"

#include <google/protobuf/util/json_util.h>

#include <charconv>
#include <cmath>
#include <cstdint>

namespace gmr::server {

namespace {

// A number as protobuf's JSON mapping writes it: the shortest text that
// reads back to the same value; NaN and the infinities as strings.
template <class T>
void append_number(std::string& out, T v) {
  if (std::isnan(v)) {
    out += "\"NaN\"";
  } else if (std::isinf(v)) {
    out += v > 0 ? "\"Infinity\"" : "\"-Infinity\"";
  } else {
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    out.append(buf, r.ptr);
  }
}

void append_uint(std::string& out, std::uint64_t v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  out.append(buf, r.ptr);
}

// "name": v, left out at its default (proto3 JSON leaves defaults out).
// 64-bit integers are strings in the mapping.
struct JsonObject {
  std::string& out;
  bool first = true;
  void key(const char* name) {
    out += first ? "\"" : ",\"";
    first = false;
    out += name;
    out += "\":";
  }
  void u32(const char* name, std::uint32_t v) {
    if (v == 0) return;
    key(name);
    append_uint(out, v);
  }
  void u64(const char* name, std::uint64_t v) {
    if (v == 0) return;
    key(name);
    out += '"';
    append_uint(out, v);
    out += '"';
  }
  void i64(const char* name, std::int64_t v) {
    if (v == 0) return;
    key(name);
    out += '"';
    if (v < 0) out += '-';
    append_uint(out, v < 0 ? 0 - static_cast<std::uint64_t>(v) : static_cast<std::uint64_t>(v));
    out += '"';
  }
  void f64(const char* name, double v) {
    if (v == 0.0 && !std::signbit(v)) return;
    key(name);
    append_number(out, v);
  }
  template <class Repeated>
  void array(const char* name, const Repeated& values) {
    if (values.empty()) return;
    key(name);
    out += '[';
    for (int i = 0; i < values.size(); ++i) {
      if (i != 0) out += ',';
      append_number(out, values.Get(i));
    }
    out += ']';
  }
};
}  // namespace

std::string frame_to_json(const pb::ServerMessage& m) {
  const pb::Frame& f = m.frame();
  std::string out;
  out.reserve(64 + 24 * static_cast<std::size_t>(f.positions_size() + f.positions_f64_size() + f.orientations_size() +
                                                 f.orientations_f64_size() + f.local_rotations_size() +
                                                 f.local_rotations_f64_size() + f.local_translations_size() +
                                                 f.local_translations_f64_size()));
  out += '{';
  JsonObject top{out};
  top.u64("requestId", m.request_id());
  top.key("frame");
  out += '{';
  JsonObject o{out};
  o.u32("viewId", f.view_id());
  o.u32("subscriptionId", f.subscription_id());
  o.u64("streamId", f.stream_id());
  o.u32("skeletonVersion", f.skeleton_version());
  o.u64("frameIndex", f.frame_index());
  o.f64("motionTime", f.motion_time());
  o.u64("sequence", f.sequence());
  o.i64("serverSendTimeNs", f.server_send_time_ns());
  o.i64("serverWriteTimeNs", f.server_write_time_ns());
  o.array("positions", f.positions());
  o.array("orientations", f.orientations());
  o.array("positionsF64", f.positions_f64());
  o.array("orientationsF64", f.orientations_f64());
  o.array("localRotations", f.local_rotations());
  o.array("localTranslations", f.local_translations());
  o.array("localRotationsF64", f.local_rotations_f64());
  o.array("localTranslationsF64", f.local_translations_f64());
  out += "}}";
  return out;
}

Result<std::string> server_message_to_json(std::string_view body) {
  pb::ServerMessage m;
  if (!m.ParseFromArray(body.data(), static_cast<int>(body.size()))) {
    return make_error("cannot parse a " + std::to_string(body.size()) + "-byte message to write it as JSON");
  }
  if (m.has_frame()) return frame_to_json(m);  // the message sent most, converted fast
  std::string json;
  if (!google::protobuf::util::MessageToJsonString(m, &json, google::protobuf::util::JsonPrintOptions()).ok()) {
    return make_error("cannot write a " + std::to_string(body.size()) + "-byte message as JSON");
  }
  return json;
}

Result<std::string> client_message_from_json(const std::string& text) {
  pb::ClientMessage m;
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = false;
  if (auto status = google::protobuf::util::JsonStringToMessage(text, &m, options); !status.ok()) {
    return make_error(std::string(status.message()));
  }
  return m.SerializeAsString();
}

}  // namespace gmr::server
