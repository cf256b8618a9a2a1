#include "gmr/ops/view.h"

#include <algorithm>

#include "gmr/convert/convert.h"
#include "gmr/kinematics/forward_kinematics.h"

namespace gmr {

Result<View> apply_view(const Motion& source, const ViewSpec& spec) {
  auto pre = to_pre_rotation(source);
  if (!pre) return pre.error();
  View view;
  view.motion = std::move(pre).value();
  if (!spec.roots.empty()) {
    auto roots = find_joints(view.motion.skeleton, spec.roots);
    if (!roots) return roots.error();
    auto m = set_roots(view.motion, *roots);
    if (!m) return m.error();
    view.motion = std::move(m).value();
  }
  if (spec.strip_dummies) {
    auto m = strip_dummies(view.motion, &view.removed);
    if (!m) return m.error();
    view.motion = std::move(m).value();
  }
  if (!spec.relative_to.empty()) {
    view.viewer = view.motion.skeleton.find(spec.relative_to);
    if (view.viewer < 0) {
      const bool was_removed = std::any_of(view.removed.begin(), view.removed.end(),
                                           [&](const RemovedJoint& r) { return r.name == spec.relative_to; });
      return make_error("unknown joint '" + spec.relative_to + "'" +
                        (was_removed ? " (removed as a zero-length joint by strip-dummies)" : ""));
    }
  }
  for (const Joint& j : source.skeleton.joints()) {
    const int k = view.motion.skeleton.find(j.name);
    if (k >= 0) view.order.push_back(k);
  }
  return view;
}

std::vector<Eigen::Vector3d> view_positions(const View& view, std::size_t begin, std::size_t end) {
  const Motion& m = view.motion;
  std::vector<Eigen::Vector3d> all;
  if (view.viewer >= 0) {
    intrinsic_positions(m, view.viewer, begin, end, all);
  } else {
    all = compute_positions(m, begin, end);
  }
  const std::size_t n = m.skeleton.size(), k = view.order.size();
  const std::size_t frames = n == 0 ? 0 : all.size() / n;
  std::vector<Eigen::Vector3d> out(frames * k);
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t i = 0; i < k; ++i) out[f * k + i] = all[f * n + static_cast<std::size_t>(view.order[i])];
  }
  return out;
}

Skeleton view_names(const View& view) {
  std::vector<Joint> joints;
  for (int j : view.order) {
    Joint joint;
    joint.name = view.motion.skeleton.joint(j).name;
    joints.push_back(std::move(joint));
  }
  auto s = Skeleton::create(std::move(joints));
  return s ? std::move(s).value() : Skeleton{};
}

}  // namespace gmr
