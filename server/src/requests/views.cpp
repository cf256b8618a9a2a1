#include "requests/views.h"

#include <Eigen/Geometry>
#include <utility>

#include "gmr/view/engine_pose.h"
#include "gmr/view/viewpoint.h"
#include "gmr/wire/convert.h"
#include "live/live_source.h"

namespace gmr::server {

Reply Views::list_motions() const {
  pb::ServerMessage out;
  auto* list = out.mutable_motions();
  for (const auto& e : link_.services.catalog.library()) {
    auto* m = list->add_motions();
    m->set_name(e.name);
    m->set_joint_count(static_cast<std::uint32_t>(e.motion->skeleton.size()));
    m->set_frame_count(e.motion->frame_count);
    m->set_frame_time(e.motion->frame_time);
    m->set_source(e.source);
    m->set_metres_per_unit(e.metres_per_unit);
    m->set_version(e.version);
  }
  for (const auto& [name, source] : link_.services.catalog.live_sources()) {
    auto* m = list->add_motions();
    m->set_name(name);
    m->set_joint_count(static_cast<std::uint32_t>(source->latest()->skeleton.size()));
    m->set_frame_count(source->frames());
    m->set_frame_time(source->frame_time());
    m->set_source("live");
    m->set_metres_per_unit(source->metres_per_unit());
    m->set_live(true);
  }
  return out;
}

Reply Views::get_skeleton(const pb::GetSkeleton& r) const {
  const Catalog::Found found = link_.services.catalog.find(r.motion());
  if (!found) return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown motion '" + r.motion() + "'"};
  if (const auto& source = found.live) {
    const auto basis = output_basis_of(r.conventions(), source->metres_per_unit());
    if (!basis.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, basis.error().message};
    pb::ServerMessage out;
    out.mutable_skeleton()->set_motion(source->name());
    wire::to_proto(*source->latest(), *basis, *out.mutable_skeleton()->mutable_skeleton());
    return out;
  }
  const LibraryEntry& e = *found.entry;
  const auto basis = output_basis_of(r.conventions(), e.metres_per_unit);
  if (!basis.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, basis.error().message};
  pb::ServerMessage out;
  out.mutable_skeleton()->set_motion(e.name);
  wire::to_proto(*e.motion, *basis, *out.mutable_skeleton()->mutable_skeleton());
  return out;
}

Reply Views::create(const pb::CreateView& r) {
  const Catalog::Found found = link_.services.catalog.find(r.motion());
  if (!found) return Refusal{pb::ERROR_CODE_NOT_FOUND, "unknown motion '" + r.motion() + "'"};
  if (views_.size() >= link_.services.cfg.max_views_per_connection) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "at most " + std::to_string(link_.services.cfg.max_views_per_connection) + " views per connection"};
  }
  const std::uint32_t id = next_view_++;
  auto v = found.live ? std::make_unique<View>(id, found.live->name(), found.live->latest(), found.live)
                      : std::make_unique<View>(id, found.entry->name, found.entry->motion,
                                               link_.services.catalog.compiled_form(found.index), found.entry->version);
  pb::ServerMessage out;
  *out.mutable_view() = info(*v);
  views_.emplace(id, std::move(v));
  return out;
}

Reply Views::commit_edit(std::uint32_t view_id, const ViewEdit& edit, Result<std::shared_ptr<const ViewContent>> next,
                         EditDecoration decorate) {
  View* v = find(view_id);
  if (!v) return unknown_view(view_id);
  if (!next.ok()) return refusal_of(next.error());
  const auto before = v->content();
  const std::uint64_t old_bytes = link_.services.catalog.owned_bytes(*v);
  if (Status s = v->commit(edit, std::move(next).value()); !s.ok()) return refusal_of(s.error());
  // The view budget: an edit whose copy would pass it is undone and refused.
  const std::uint64_t new_bytes = link_.services.catalog.owned_bytes(*v);
  const ServerConfig& cfg = link_.services.cfg;
  const std::uint64_t mine = link_.held_bytes - old_bytes + new_bytes;
  const std::uint64_t all = link_.services.admission.view_bytes() - old_bytes + new_bytes;
  if (new_bytes > old_bytes && (mine > cfg.max_view_bytes_per_connection || all > cfg.max_view_bytes)) {
    v->restore(before);
    const bool own = mine > cfg.max_view_bytes_per_connection;
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "the edited view would hold " + std::to_string(new_bytes) + " bytes of motion; views " +
                       (own ? "of this connection" : "of all connections") + " would then hold " +
                       std::to_string(own ? mine : all) + " bytes, above the server's limit of " +
                       std::to_string(own ? cfg.max_view_bytes_per_connection : cfg.max_view_bytes) +
                       ": close views you no longer use"};
  }
  link_.held_bytes = mine;
  link_.services.admission.set_view_bytes(all);
  if (changed_) changed_(*v);
  pb::ServerMessage out;
  *out.mutable_view() = info(*v);
  if (decorate != nullptr) decorate(edit.report(), *out.mutable_view());
  return out;
}

Reply Views::set_coordinates(const pb::SetCoordinates& r) {
  View* v = find(r.view_id());
  if (!v) return unknown_view(r.view_id());
  if (Status s = v->set_relative_to(r.relative_to()); !s.ok()) return refusal_of(s.error());
  if (changed_) changed_(*v);  // the same motion: the same bytes
  pb::ServerMessage out;
  *out.mutable_view() = info(*v);
  return out;
}

Reply Views::query(const pb::QueryFrames& r) const {
  const View* v = find(r.view_id());
  if (!v) return unknown_view(r.view_id());
  if (auto why = link_.services.catalog.stale(*v->content()); !why.empty()) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, why};
  }
  // A live view's one frame is its source's newest (the last it had, once
  // the source ended).
  std::shared_ptr<const Motion> newest = v->content()->motion;
  if (auto source = v->live_source(); source && !source->ended()) {
    auto now = source->view_motion(*v->content());
    if (!now.ok()) return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION, now.error().to_string()};
    newest = std::move(now).value();
  }
  const Motion& m = *newest;
  const std::uint64_t begin = r.begin();
  const std::uint64_t end = r.end() == 0 ? begin + 1 : r.end();
  if (!(begin < end && end <= m.frame_count)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "frames [" + std::to_string(begin) + ", " + std::to_string(end) +
                                                   ") are not within the motion's " + std::to_string(m.frame_count) +
                                                   " frames"};
  }
  auto joints = resolve_joints(*v, {r.joints().begin(), r.joints().end()});
  if (!joints.ok()) return Refusal{pb::ERROR_CODE_NOT_FOUND, joints.error().message};
  const auto basis = output_basis_of(r.conventions(), link_.services.catalog.metres_per_unit(*v));
  if (!basis.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, basis.error().message};
  // Refuse before computing anything a reply too big to send.
  const std::uint64_t per_frame =
      joints->size() * (3 + (r.orientations() ? 4 : 0) + (r.local_transforms() ? 7 : 0)) * 9 + 8;
  const std::uint64_t estimate = (end - begin) * per_frame + 64;
  if (estimate > link_.services.cfg.max_message_bytes) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   "a query of " + std::to_string(end - begin) + " frames would take about " +
                       std::to_string(estimate) + " bytes, above the limit of " +
                       std::to_string(link_.services.cfg.max_message_bytes) + ": ask for fewer frames"};
  }
  pb::ServerMessage out;
  auto* b = out.mutable_frames();
  b->set_view_id(v->id());
  b->set_skeleton_version(v->content()->skeleton_version);
  b->set_metres_per_unit(basis->metres_per_unit);
  b->set_begin(static_cast<std::uint32_t>(begin));
  b->set_end(static_cast<std::uint32_t>(end));
  for (int j : *joints) b->add_joints(static_cast<std::uint32_t>(j));
  const std::size_t n = m.skeleton.size();
  const int viewer = v->content()->relative_to;
  std::vector<Eigen::Vector3d> pos(n);
  std::vector<Eigen::Matrix3d> rot(r.orientations() || viewer >= 0 || r.local_transforms() ? n : 0);
  const std::vector<int> own_frames = r.local_transforms() ? own_frame_sources(m) : std::vector<int>{};
  std::vector<Eigen::Quaterniond> local_rotations(r.local_transforms() ? joints->size() : 0);
  std::vector<Eigen::Vector3d> local_translations(local_rotations.size());
  b->mutable_positions()->Reserve(static_cast<int>((end - begin) * joints->size() * 3));
  for (std::uint64_t f = begin; f < end; ++f) {
    view_frame(m, viewer, f, pos, rot, *basis);
    if (r.local_transforms()) {
      engine_locals(m.skeleton, own_frames, pos, rot, *joints, local_rotations, local_translations);
      for (std::size_t i = 0; i < joints->size(); ++i) {
        const auto& q = local_rotations[i];
        const auto& t = local_translations[i];
        const double qv[] = {q.x(), q.y(), q.z(), q.w()}, tv[] = {t.x(), t.y(), t.z()};
        b->mutable_local_rotations()->Add(std::begin(qv), std::end(qv));
        b->mutable_local_translations()->Add(std::begin(tv), std::end(tv));
      }
    }
    for (int j : *joints) {
      const auto& p = pos[static_cast<std::size_t>(j)];
      b->add_positions(p.x());
      b->add_positions(p.y());
      b->add_positions(p.z());
      if (r.orientations()) {
        const Eigen::Quaterniond q(rot[static_cast<std::size_t>(j)]);
        b->add_orientations(q.x());
        b->add_orientations(q.y());
        b->add_orientations(q.z());
        b->add_orientations(q.w());
      }
    }
  }
  return out;
}

void Views::forget(const View& v) {
  const std::uint64_t bytes = link_.services.catalog.owned_bytes(v);
  link_.held_bytes -= bytes;
  link_.services.admission.release_view_bytes(bytes);
}

View* Views::find(std::uint32_t id) const {
  auto it = views_.find(id);
  return it == views_.end() ? nullptr : it->second.get();
}

Result<std::vector<int>> Views::resolve_joints(const View& v, const std::vector<std::string>& names) const {
  std::vector<int> out;
  if (names.empty()) {
    for (int j = 0; j < static_cast<int>(v.motion().skeleton.size()); ++j) out.push_back(j);
    return out;
  }
  for (const auto& n : names) {
    auto j = v.joint_index(n);
    if (!j.ok()) return j.error();
    out.push_back(*j);
  }
  return out;
}

pb::ViewInfo Views::info(const View& v) const {
  pb::ViewInfo info;
  info.set_view_id(v.id());
  info.set_motion(v.motion_name());
  info.set_skeleton_version(v.content()->skeleton_version);
  OutputBasis native;  // the motion's own axes and unit
  native.metres_per_unit = link_.services.catalog.metres_per_unit(v);
  wire::to_proto(v.motion(), native, *info.mutable_skeleton());
  if (v.content()->relative_to >= 0) info.set_relative_to(v.motion().skeleton.joint(v.content()->relative_to).name);
  info.set_frame_count(v.motion().frame_count);
  info.set_frame_time(v.motion().frame_time);
  return info;
}

void Views::close(std::uint32_t id) {
  auto it = views_.find(id);
  if (it == views_.end()) return;
  forget(*it->second);
  views_.erase(it);
}

void Views::clear() {
  for (const auto& [id, v] : views_) forget(*v);
  views_.clear();
}

}  // namespace gmr::server
