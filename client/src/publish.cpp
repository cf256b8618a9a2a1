#include "client_impl.h"

namespace gmr::client {

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

Status Client::publish_frame(std::uint32_t publication, std::span<const double> values) {
  pb::ClientMessage m;
  m.set_request_id(impl_->next_request++);  // an Error for it names this id
  auto* f = m.mutable_publish_frame();
  f->set_publication_id(publication);
  f->mutable_values()->Add(values.begin(), values.end());
  auto framed = wire::frame_message(m, impl_->hello.max_message_bytes != 0 ? impl_->hello.max_message_bytes : 1u << 30);
  if (!framed.ok()) return framed.error();
  {
    std::lock_guard lock(impl_->mutex);
    if (!impl_->open) return make_error("not connected: " + impl_->close_reason);
  }
  if (!impl_->send(std::move(framed).value())) {
    return make_error(ErrorKind::kResourceExhausted,
                      "write queue full: the server is not reading this client's frames");
  }
  return Ok{};
}

Status Client::unpublish(std::uint32_t publication) {
  pb::ClientMessage m;
  m.mutable_unpublish()->set_publication_id(publication);
  return to_status(impl_->expect(m, pb::ServerMessage::kAck));
}

}  // namespace gmr::client
