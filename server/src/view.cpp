#include "gmr/server/view.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <exception>
#include <new>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/ops.h"

namespace gmr::server {

CompiledForm::CompiledForm(std::shared_ptr<const Motion> motion) : motion_(std::move(motion)) {}
CompiledForm::~CompiledForm() = default;

const fast::CompiledMotion* CompiledForm::get() const {
  std::call_once(once_, [this] {
    if (!motion_) return;
    const auto joints = motion_->skeleton.size();
    const auto frames = motion_->frame_count;
    try {
      auto c = fast::CompiledMotion::compile(*motion_);
      if (!c.ok()) {
        spdlog::warn("float32 streams of a motion ({} joints, {} frames) use the double path: {}", joints, frames,
                     c.error().to_string());
        return;
      }
      if (c->joint_count() != joints || c->frame_count() != frames) {
        spdlog::warn("float32 streams of a motion ({} joints, {} frames) use the double path: "
                     "its compiled form has {} joints, {} frames",
                     joints, frames, c->joint_count(), c->frame_count());
        return;
      }
      auto owned = std::make_unique<const fast::CompiledMotion>(std::move(c).value());
      workspace_floats_ = fast::fk_workspace_size(*owned);
      compiled_ = std::move(owned);
    } catch (const std::exception& e) {  // std::bad_alloc for an absurdly large motion
      spdlog::warn("float32 streams of a motion ({} joints, {} frames) use the double path: compiling failed: {}",
                   joints, frames, e.what());
      compiled_.reset();
      workspace_floats_ = 0;
    }
  });
  return compiled_.get();
}

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

namespace {

// The viewpoint of joint v applied to float FK outputs, in double:
// P'_j = W_v^T (P_j - P_v), W'_j = W_v^T W_j (W row-major 3x3).
void float_to_view(const float* pos, const float* orient, std::size_t n, int relative_to,
                   std::span<Eigen::Vector3d> out_positions, std::span<Eigen::Matrix3d> out_orientations) {
  if (relative_to < 0) {
    for (std::size_t j = 0; j < n; ++j) {
      out_positions[j] = Eigen::Vector3d(pos[3 * j], pos[3 * j + 1], pos[3 * j + 2]);
    }
    if (!out_orientations.empty()) {
      for (std::size_t j = 0; j < n; ++j) {
        const float* w = orient + 9 * j;
        auto& o = out_orientations[j];
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < 3; ++c) o(r, c) = w[3 * r + c];
        }
      }
    }
    return;
  }
  const auto v = static_cast<std::size_t>(relative_to);
  double wv[9];  // W_v, row-major
  for (int k = 0; k < 9; ++k) wv[k] = orient[9 * v + static_cast<std::size_t>(k)];
  const double pv[3] = {pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]};
  for (std::size_t j = 0; j < n; ++j) {
    const double d0 = static_cast<double>(pos[3 * j]) - pv[0];
    const double d1 = static_cast<double>(pos[3 * j + 1]) - pv[1];
    const double d2 = static_cast<double>(pos[3 * j + 2]) - pv[2];
    auto& p = out_positions[j];
    for (int r = 0; r < 3; ++r) p[r] = wv[r] * d0 + wv[3 + r] * d1 + wv[6 + r] * d2;  // (W^T)_{r k} = W_{k r}
  }
  if (!out_orientations.empty()) {
    for (std::size_t j = 0; j < n; ++j) {
      const float* w = orient + 9 * j;
      auto& o = out_orientations[j];
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
          o(r, c) = wv[r] * static_cast<double>(w[c]) + wv[3 + r] * static_cast<double>(w[3 + c]) +
                    wv[6 + r] * static_cast<double>(w[6 + c]);
        }
      }
    }
  }
}

}  // namespace

FramePath compute_stream_frame(const ViewContent& view, std::size_t f, bool float32, FloatFrameBuffers& buffers,
                               std::span<Eigen::Vector3d> out_positions, std::span<Eigen::Matrix3d> out_orientations) {
  const fast::CompiledMotion* cm = float32 && view.compiled ? view.compiled->get() : nullptr;
  const std::size_t n = view.motion->skeleton.size();
  if (cm != nullptr && cm->joint_count() == n && f < cm->frame_count() && out_positions.size() >= n &&
      view.relative_to < static_cast<int>(n) &&
      (out_orientations.empty() || out_orientations.size() >= n)) {
    // The viewer's orientation is needed even when the caller wants none.
    const bool orient = !out_orientations.empty() || view.relative_to >= 0;
    buffers.positions.resize(n * 3);
    buffers.orientations.resize(orient ? n * 9 : 0);
    buffers.workspace.resize(std::max(buffers.workspace.size(), view.compiled->workspace_floats()));
    fast::FkFrameJob job;
    job.motion = cm;
    job.frame = f;
    job.out_positions = buffers.positions;
    job.out_orientations = buffers.orientations;
    job.workspace = buffers.workspace;
    if (job.run()) {
      float_to_view(buffers.positions.data(), buffers.orientations.data(), n, view.relative_to, out_positions,
                    out_orientations);
      return FramePath::kFloat;
    }
  }
  compute_view_frame(view, f, out_positions, out_orientations);
  return FramePath::kDouble;
}

View::View(std::uint32_t id, std::string motion_name, std::shared_ptr<const Motion> motion,
           std::shared_ptr<const CompiledForm> compiled)
    : id_(id), motion_name_(std::move(motion_name)) {
  auto c = std::make_shared<ViewContent>();
  if (!compiled || compiled->motion() != motion) compiled = std::make_shared<const CompiledForm>(motion);
  c->motion = std::move(motion);
  c->compiled = std::move(compiled);
  content_ = std::move(c);
}

Result<int> View::joint_index(const std::string& name) const {
  const int j = motion().skeleton.find(name);
  if (j < 0) {
    return make_error("view " + std::to_string(id_) + " (" + motion_name_ + ") has no joint '" + name + "'");
  }
  return j;
}

void View::replace(std::shared_ptr<const Motion> motion, int relative_to,
                   std::shared_ptr<const CompiledForm> compiled) {
  auto c = std::make_shared<ViewContent>();
  if (!compiled || compiled->motion() != motion) compiled = std::make_shared<const CompiledForm>(motion);
  c->motion = std::move(motion);
  c->compiled = std::move(compiled);
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
  replace(content_->motion, viewer, content_->compiled);  // same motion: same float form
  return Ok{};
}

}  // namespace gmr::server
