#include "gmr/server/view.h"

#include <algorithm>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/ops.h"

namespace gmr::server {

void compute_view_frame(const ViewContent& view, std::size_t f, std::span<Eigen::Vector3d> out_positions,
                        std::span<Eigen::Matrix3d> out_orientations) {
  const Motion& m = *view.motion;
  if (view.relative_to < 0) {
    compute_frame(m, f, out_positions, out_orientations);
    return;
  }
  // The viewer's frame is needed even when the caller wants no orientations.
  thread_local std::vector<Eigen::Matrix3d> scratch;
  std::span<Eigen::Matrix3d> orient = out_orientations;
  if (orient.empty()) {
    scratch.resize(m.skeleton.size());
    orient = scratch;
  }
  compute_frame(m, f, out_positions, orient);
  const auto v = static_cast<std::size_t>(view.relative_to);
  const Eigen::Matrix3d wt = orient[v].transpose();
  const Eigen::Vector3d pv = out_positions[v];
  for (auto& p : out_positions) p = wt * (p - pv);
  if (!out_orientations.empty()) {
    for (auto& w : out_orientations) w = wt * w;
  }
}

View::View(std::uint32_t id, std::string motion_name, std::shared_ptr<const Motion> motion)
    : id_(id), motion_name_(std::move(motion_name)) {
  auto c = std::make_shared<ViewContent>();
  c->motion = std::move(motion);
  content_ = std::move(c);
}

Result<int> View::joint_index(const std::string& name) const {
  const int j = motion().skeleton.find(name);
  if (j < 0) {
    return make_error("view " + std::to_string(id_) + " (" + motion_name_ + ") has no joint '" + name + "'");
  }
  return j;
}

void View::replace(std::shared_ptr<const Motion> motion, int relative_to) {
  auto c = std::make_shared<ViewContent>();
  c->motion = std::move(motion);
  c->relative_to = relative_to;
  c->skeleton_version = content_->skeleton_version + 1;
  content_ = std::move(c);
}

namespace {

// Applies an op's result, keeping the viewer joint (by name) when it survived.
Status adopt(View& view, Result<Motion> result, const std::string& what,
             const std::function<void(std::shared_ptr<const Motion>, int)>& replace) {
  if (!result.ok()) return make_error(what + ": " + result.error().to_string());
  auto next = std::make_shared<const Motion>(std::move(result).value());
  int viewer = -1;
  if (view.content()->relative_to >= 0) {
    const std::string& name = view.motion().skeleton.joint(view.content()->relative_to).name;
    viewer = next->skeleton.find(name);
    if (viewer < 0) return make_error(what + ": it would remove the viewer joint '" + name + "'");
  }
  replace(std::move(next), viewer);
  return Ok{};
}

}  // namespace

Status View::shift_root(const std::string& joint) {
  auto j = joint_index(joint);
  if (!j.ok()) return j.error();
  return adopt(*this, gmr::shift_root(motion(), *j), "shift root to '" + joint + "'",
               [this](auto m, int v) { replace(std::move(m), v); });
}

Status View::split(const std::string& joint) {
  auto j = joint_index(joint);
  if (!j.ok()) return j.error();
  if (motion().skeleton.is_root(*j)) return make_error("split at '" + joint + "': it is already a root");
  return adopt(*this, split_tree(motion(), *j), "split at '" + joint + "'",
               [this](auto m, int v) { replace(std::move(m), v); });
}

Status View::join(const std::string& root, double* out_offset_spread) {
  auto j = joint_index(root);
  if (!j.ok()) return j.error();
  JoinReport report;
  auto s = adopt(*this, join_tree(motion(), *j, &report), "join '" + root + "'",
                 [this](auto m, int v) { replace(std::move(m), v); });
  if (s.ok() && out_offset_spread) *out_offset_spread = report.offset_spread;
  return s;
}

Status View::set_roots(const std::vector<std::string>& roots) {
  if (roots.empty()) return make_error("set roots: give at least one root");
  std::vector<int> idx;
  for (const auto& r : roots) {
    auto j = joint_index(r);
    if (!j.ok()) return j.error();
    idx.push_back(*j);
  }
  return adopt(*this, gmr::set_roots(motion(), idx), "set roots", [this](auto m, int v) { replace(std::move(m), v); });
}

Status View::strip_dummies(std::vector<std::string>* out_removed) {
  std::vector<RemovedJoint> removed;
  auto s = adopt(*this, gmr::strip_dummies(motion(), &removed), "strip dummies",
                 [this](auto m, int v) { replace(std::move(m), v); });
  if (s.ok() && out_removed) {
    for (const auto& r : removed) out_removed->push_back(r.name);
  }
  return s;
}

Status View::set_relative_to(const std::string& joint) {
  int viewer = -1;
  if (!joint.empty()) {
    auto j = joint_index(joint);
    if (!j.ok()) return j.error();
    viewer = *j;
  }
  replace(content_->motion, viewer);
  return Ok{};
}

}  // namespace gmr::server
