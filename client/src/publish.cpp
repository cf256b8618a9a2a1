#include "client_impl.h"

#include <cmath>

namespace gmr::client {

namespace {

// A PublishFrame `m` queued without waiting for a reply (the client's Impl,
// a private type, is deduced).
template <class Impl>
Status send_frame(Impl& impl, std::uint32_t publication, pb::ClientMessage& m) {
  m.set_request_id(impl.next_request++);  // an Error for it names this id
  m.mutable_publish_frame()->set_publication_id(publication);
  auto framed = wire::frame_message(m, impl.hello.max_message_bytes != 0 ? impl.hello.max_message_bytes : 1u << 30);
  if (!framed.ok()) return framed.error();
  {
    std::lock_guard lock(impl.mutex);
    if (!impl.open) return make_error("not connected: " + impl.close_reason);
  }
  if (!impl.send(std::move(framed).value())) {
    return make_error(ErrorKind::kResourceExhausted,
                      "write queue full: the server is not reading this client's frames");
  }
  return Ok{};
}

}  // namespace

Result<Publication> Client::publish(const Skeleton& skeleton, const PublishOptions& options) {
  pb::ClientMessage m;
  auto* p = m.mutable_publish();
  p->set_name(options.name);
  wire::to_proto(skeleton, *p->mutable_skeleton());
  p->set_frame_time(options.frame_time);
  p->set_metres_per_unit(options.metres_per_unit);
  p->set_record(options.record);
  auto r = impl_->expect(m, pb::ServerMessage::kPublished);
  if (!r.ok()) return r.error();
  return Publication{r->published().publication_id(), r->published().motion(), r->published().recording()};
}

Result<Publication> Client::publish_markers(std::span<const std::string> marker_names,
                                            const MarkerPublishOptions& options) {
  pb::ClientMessage m;
  auto* p = m.mutable_publish();
  p->set_name(options.name);
  p->set_frame_time(options.frame_time);
  auto* markers = p->mutable_markers();
  for (const std::string& n : marker_names) markers->add_names(n);
  markers->set_model(options.model);
  markers->set_calibration_seconds(options.calibration_seconds);
  markers->set_units(options.units);
  p->set_record(options.record);
  auto r = impl_->expect(m, pb::ServerMessage::kPublished);
  if (!r.ok()) return r.error();
  return Publication{r->published().publication_id(), r->published().motion(), r->published().recording()};
}

Status Client::publish_marker_frame(std::uint32_t publication, std::span<const double> positions) {
  pb::ClientMessage m;
  auto* f = m.mutable_publish_frame();
  for (std::size_t i = 0; i + 2 < positions.size(); i += 3) {
    if (std::isnan(positions[i]) || std::isnan(positions[i + 1]) || std::isnan(positions[i + 2])) {
      f->add_missing_markers(static_cast<std::uint32_t>(i / 3));
      f->add_values(0.0);
      f->add_values(0.0);
      f->add_values(0.0);
    } else {
      f->add_values(positions[i]);
      f->add_values(positions[i + 1]);
      f->add_values(positions[i + 2]);
    }
  }
  for (std::size_t i = positions.size() / 3 * 3; i < positions.size(); ++i) f->add_values(positions[i]);
  return send_frame(*impl_, publication, m);
}

Status Client::publish_frame(std::uint32_t publication, std::span<const double> values) {
  pb::ClientMessage m;
  m.mutable_publish_frame()->mutable_values()->Add(values.begin(), values.end());
  return send_frame(*impl_, publication, m);
}

Status Client::unpublish(std::uint32_t publication) {
  pb::ClientMessage m;
  m.mutable_unpublish()->set_publication_id(publication);
  return to_status(impl_->expect(m, pb::ServerMessage::kAck));
}

}  // namespace gmr::client
