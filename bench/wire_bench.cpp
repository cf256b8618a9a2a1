// What a pushed frame costs on the wire side, per transport's encoding: the
// shared binary body (once per stream and tick), the per-subscriber head, and
// the conversion to protobuf's JSON mapping that a WebSocket JSON subscriber
// (the browser viewer) costs per frame (docs/protocol.md, "WebSocket"): by
// protobuf's MessageToJsonString, and by the server's frame_to_json.
// A frame of 38 joints (CMU's BVH skeleton with its end sites), float64;
// the body also as a pb::Frame serialized (what encode_frame_body did once);
// and a client's decoding of a frame, two ways.
#include <benchmark/benchmark.h>
#include <google/protobuf/util/json_util.h>

#include <random>
#include <vector>

#include "gmr/wire/frames.h"
#ifdef GMR_HAVE_SERVER
#include "transport/ws_json.h"
#endif

namespace gmr::bench {
namespace {

constexpr std::size_t kJoints = 38;

std::vector<double> positions() {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> d(-100.0, 100.0);
  std::vector<double> p(kJoints * 3);
  for (auto& v : p) v = d(rng);
  return p;
}

// A frame's fields but its values.
wire::FrameContent header() {
  wire::FrameContent c;
  c.skeleton_version = 3;
  c.frame_index = 1234;
  c.motion_time = 10.28;
  c.sequence = 99999;
  c.server_send_time_ns = 1795000000000000000;
  return c;
}

std::string body() {
  static const std::vector<double> p = positions();
  wire::FrameContent c = header();
  c.float64 = true;
  c.positions_f64 = p;
  return wire::encode_frame_body(c);
}

void BM_EncodeBody(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(body());
}
BENCHMARK(BM_EncodeBody)->Name("frame/encode_body_f64");

// What an own stream of CMU 01_01 sends: float32 positions of its 31 joints.
void BM_EncodeBodyF32(benchmark::State& state) {
  static const std::vector<double> p = positions();
  const std::vector<float> f(p.begin(), p.begin() + 31 * 3);
  wire::FrameContent c = header();
  c.positions = f;
  for (auto _ : state) benchmark::DoNotOptimize(wire::encode_frame_body(c));
}
BENCHMARK(BM_EncodeBodyF32)->Name("frame/encode_body_f32_31_joints");

// The same body through a pb::Frame, as encode_frame_body did before it
// wrote the fields itself (the reference for its figure).
void BM_EncodeBodyByProtobuf(benchmark::State& state) {
  const std::vector<double> p = positions();
  for (auto _ : state) {
    ::gmr::stream::v1::Frame f;
    f.set_skeleton_version(3);
    f.set_frame_index(1234);
    f.set_motion_time(10.28);
    f.set_sequence(99999);
    f.set_server_send_time_ns(1795000000000000000);
    f.mutable_positions_f64()->Add(p.begin(), p.end());
    benchmark::DoNotOptimize(f.SerializeAsString());
  }
}
BENCHMARK(BM_EncodeBodyByProtobuf)->Name("frame/encode_body_f64_through_protobuf");

void BM_Head(benchmark::State& state) {
  const std::string b = body();
  for (auto _ : state) benchmark::DoNotOptimize(wire::frame_head_for(1, 2, 3, b.size(), false).size());
}
BENCHMARK(BM_Head)->Name("frame/subscriber_head");

// What a client does with each frame that arrives: a CMU 01_01 frame as
// gmr-load and the plugins get it (float32 positions), whole ServerMessage
// bytes to values. Through protobuf (parse, then decode_frame: what the C++
// client did) and read in place into a FrameValues kept between frames.
std::string float32_message() {
  static const std::vector<double> p = positions();
  const std::vector<float> pf(p.begin(), p.end());
  wire::FrameContent c = header();
  c.positions = pf;
  return wire::frame_message_for(1, 2, 3, wire::encode_frame_body(c), 1795000000000100000);
}

void BM_DecodeByProtobuf(benchmark::State& state) {
  const std::string message = float32_message();
  for (auto _ : state) {
    ::gmr::stream::v1::ServerMessage m;
    m.ParseFromArray(message.data(), static_cast<int>(message.size()));
    auto values = wire::decode_frame(m.frame());
    benchmark::DoNotOptimize(values->positions.data());
  }
  state.counters["bytes"] = static_cast<double>(message.size());
}
BENCHMARK(BM_DecodeByProtobuf)->Name("frame/decode_through_protobuf");

void BM_DecodeInPlace(benchmark::State& state) {
  const std::string message = float32_message();
  wire::FrameValues values;
  for (auto _ : state) {
    wire::FrameFields fields;
    if (!wire::read_frame_message(message, fields)) state.SkipWithError("not read");
    (void)wire::unpack_frame(fields, values);
    benchmark::DoNotOptimize(values.positions.data());
  }
}
BENCHMARK(BM_DecodeInPlace)->Name("frame/decode_read_in_place");

void BM_ToJson(benchmark::State& state) {
  const std::string message = wire::frame_message_for(1, 2, 3, body());
  google::protobuf::util::JsonPrintOptions options;
  std::size_t bytes = 0;
  for (auto _ : state) {
    ::gmr::stream::v1::ServerMessage m;
    m.ParseFromString(message);
    std::string json;
    (void)google::protobuf::util::MessageToJsonString(m, &json, options);
    bytes = json.size();
    benchmark::DoNotOptimize(json);
  }
  state.counters["binary_bytes"] = static_cast<double>(message.size());
  state.counters["json_bytes"] = static_cast<double>(bytes);
}
BENCHMARK(BM_ToJson)->Name("frame/protobuf_json");

#ifdef GMR_HAVE_SERVER
// What the WebSocket actually does per JSON subscriber and frame: parse the
// binary message, write the mapping by hand.
void BM_FastJson(benchmark::State& state) {
  const std::string message = wire::frame_message_for(1, 2, 3, body());
  std::size_t bytes = 0;
  for (auto _ : state) {
    ::gmr::stream::v1::ServerMessage m;
    m.ParseFromString(message);
    std::string json = server::frame_to_json(m);
    bytes = json.size();
    benchmark::DoNotOptimize(json);
  }
  state.counters["json_bytes"] = static_cast<double>(bytes);
}
BENCHMARK(BM_FastJson)->Name("frame/websocket_json");
#endif

}  // namespace
}  // namespace gmr::bench

BENCHMARK_MAIN();
