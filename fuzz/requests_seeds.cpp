// Seeds for gmr_fuzz_requests (requests_fuzz.cpp): the request sequences of
// real sessions on the built-in library, in the harness's record format.
// scripts/fuzz.sh runs it into the harness's corpus; nothing binary is kept
// in the repository.
//   gmr_fuzz_requests_seeds DIR
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "gmr/relay/v1/relay.pb.h"
#include "gmr/server/library.h"
#include "gmr/stream/v1/stream.pb.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/framing.h"

namespace pb = gmr::stream::v1;

namespace {

class Seed {
 public:
  Seed& request(pb::ClientMessage m) {
    m.set_request_id(++id_);
    return record(0, m.SerializeAsString());
  }
  Seed& relay(const gmr::relay::v1::LiveRelay& m) { return record(1, m.SerializeAsString()); }
  const std::string& bytes() const { return bytes_; }

 private:
  Seed& record(std::uint8_t kind, const std::string& body) {
    if (body.size() > 0xffff) return *this;
    bytes_ += static_cast<char>(kind);
    bytes_ += static_cast<char>(body.size() & 0xff);
    bytes_ += static_cast<char>(body.size() >> 8);
    bytes_ += body;
    return *this;
  }
  std::string bytes_;
  std::uint64_t id_ = 0;
};

pb::ClientMessage hello() {
  pb::ClientMessage m;
  m.mutable_hello()->set_protocol_version(gmr::wire::kProtocolVersion);
  m.mutable_hello()->set_client_name("seed");
  return m;
}

pb::ClientMessage create_view(const std::string& motion) {
  pb::ClientMessage m;
  m.mutable_create_view()->set_motion(motion);
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s DIR\n", argv[0]);
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  std::filesystem::create_directories(dir);
  const auto library = gmr::server::builtin_library();
  std::vector<Seed> seeds;
  for (const auto& entry : library) {
    const gmr::Skeleton& sk = entry.motion->skeleton;
    const std::string root = sk.joint(0).name;
    const std::string mid = sk.joint(static_cast<int>(sk.size() / 2)).name;
    const std::string last = sk.joint(static_cast<int>(sk.size() - 1)).name;

    // Views: every structural edit, queries in an engine's conventions.
    Seed s;
    s.request(hello()).request(create_view(entry.name));
    pb::ClientMessage m;
    m.mutable_list_motions();
    s.request(m);
    m.Clear();
    m.mutable_get_skeleton()->set_motion(entry.name);
    m.mutable_get_skeleton()->mutable_conventions()->set_preset(pb::CONVENTION_PRESET_UNITY);
    s.request(m);
    m.Clear();
    m.mutable_shift_root()->set_view_id(1);
    m.mutable_shift_root()->set_joint(mid);
    s.request(m);
    m.Clear();
    m.mutable_split()->set_view_id(1);
    m.mutable_split()->set_joint(last);
    s.request(m);
    m.Clear();
    m.mutable_join()->set_view_id(1);
    m.mutable_join()->set_root(last);
    s.request(m);
    m.Clear();
    m.mutable_set_roots()->set_view_id(1);
    m.mutable_set_roots()->add_roots(root);
    m.mutable_set_roots()->add_roots(last);
    s.request(m);
    m.Clear();
    m.mutable_strip_dummies()->set_view_id(1);
    s.request(m);
    m.Clear();
    m.mutable_set_coordinates()->set_view_id(1);
    m.mutable_set_coordinates()->set_relative_to(mid);
    s.request(m);
    m.Clear();
    auto* q = m.mutable_query_frames();
    q->set_view_id(1);
    q->set_begin(0);
    q->set_end(std::min<std::uint32_t>(4, static_cast<std::uint32_t>(entry.motion->frame_count)));
    q->set_orientations(true);
    q->set_local_transforms(true);
    q->add_joints(mid);
    q->mutable_conventions()->set_preset(pb::CONVENTION_PRESET_UNREAL);
    q->mutable_conventions()->set_source_metres_per_unit(0.01);
    s.request(m);
    m.Clear();
    m.mutable_close_view()->set_view_id(1);
    s.request(m);
    seeds.push_back(s);

    // Subscriptions: own and shared, then pause, seek, resume, unsubscribe.
    Seed t;
    t.request(hello()).request(create_view(entry.name)).request(create_view(entry.name));
    for (std::uint32_t view : {1u, 2u}) {
      m.Clear();
      auto* sub = m.mutable_subscribe();
      sub->set_view_id(view);
      sub->set_rate_hz(view == 1 ? 60 : 0);
      sub->set_loop(view == 1);
      sub->set_shared(view == 2);
      sub->set_orientations(true);
      sub->set_precision(view == 1 ? pb::PRECISION_FLOAT32 : pb::PRECISION_FLOAT64);
      sub->add_joints(root);
      sub->set_max_frames(10);
      sub->mutable_conventions()->set_preset(pb::CONVENTION_PRESET_GODOT);
      t.request(m);
    }
    m.Clear();
    m.mutable_pause()->set_subscription_id(1);
    t.request(m);
    m.Clear();
    m.mutable_seek()->set_subscription_id(1);
    m.mutable_seek()->set_frame(3);
    t.request(m);
    m.Clear();
    m.mutable_resume()->set_subscription_id(1);
    t.request(m);
    m.Clear();
    m.mutable_shift_root()->set_view_id(2);
    m.mutable_shift_root()->set_joint(last);
    t.request(m);
    m.Clear();
    m.mutable_unsubscribe()->set_subscription_id(2);
    t.request(m);
    m.Clear();
    m.mutable_get_stats();
    t.request(m);
    m.Clear();
    m.mutable_heartbeat()->set_client_time_ns(1);
    t.request(m);
    seeds.push_back(t);

    // A live source: published here, framed, viewed, subscribed, ended; and
    // the same source announced by another replica.
    Seed u;
    u.request(hello());
    m.Clear();
    auto* p = m.mutable_publish();
    p->set_name("live/" + entry.name);
    gmr::wire::to_proto(sk, *p->mutable_skeleton());
    p->set_frame_time(entry.motion->frame_time > 0 ? entry.motion->frame_time : 1.0 / 30);
    p->set_metres_per_unit(0.01);
    const pb::Publish announced = *p;
    u.request(m);
    for (std::size_t f = 0; f < std::min<std::size_t>(3, entry.motion->frame_count); ++f) {
      m.Clear();
      m.mutable_publish_frame()->set_publication_id(1);
      for (double v : entry.motion->frame(f)) m.mutable_publish_frame()->add_values(v);
      u.request(m);
    }
    u.request(create_view("live/" + entry.name));
    m.Clear();
    m.mutable_subscribe()->set_view_id(1);
    u.request(m);
    m.Clear();
    m.mutable_unpublish()->set_publication_id(1);
    u.request(m);
    gmr::relay::v1::LiveRelay r;
    r.set_serial(7);
    *r.mutable_announce() = announced;
    r.mutable_announce()->set_name("remote/" + entry.name);
    u.relay(r);
    r.Clear();
    r.set_serial(7);
    r.mutable_frame()->set_index(0);
    for (double v : entry.motion->frame(0)) r.mutable_frame()->add_values(v);
    u.relay(r);
    u.request(create_view("remote/" + entry.name));
    r.Clear();
    r.set_serial(7);
    r.set_end("seed");
    u.relay(r);
    seeds.push_back(u);
  }
  for (std::size_t i = 0; i < seeds.size(); ++i) {
    std::ofstream out(dir / ("session-" + std::to_string(i)), std::ios::binary);
    out << seeds[i].bytes();
    if (!out) {
      std::fprintf(stderr, "cannot write %s\n", (dir / ("session-" + std::to_string(i))).c_str());
      return 1;
    }
  }
  std::printf("%zu seeds in %s\n", seeds.size(), dir.c_str());
  return 0;
}
