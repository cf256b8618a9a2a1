#include "gmr/view/view.h"

#include <algorithm>

#include "gmr/ops/convert.h"
#include "gmr/ops/set_roots.h"
#include "gmr/view/viewpoint.h"

namespace gmr {

Result<MotionView> apply_view(const Motion& source, const ViewSpec& spec) {
  auto pre = to_pre_rotation(source);
  if (!pre) return pre.error();
  MotionView view;
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
      const auto it = std::find_if(view.removed.begin(), view.removed.end(),
                                   [&](const RemovedJoint& r) { return r.name == spec.relative_to; });
      return make_error("unknown joint '" + spec.relative_to + "'" +
                        (it != view.removed.end()
                             ? " (zero-length: merged into '" + it->merged_into + "' by strip-dummies)"
                             : std::string()));
    }
  }
  for (const Joint& j : source.skeleton.joints()) {
    const int k = view.motion.skeleton.find(j.name);
    if (k >= 0) view.order.push_back(k);
  }
  return view;
}

std::vector<Eigen::Vector3d> view_positions(const MotionView& view, std::size_t begin, std::size_t end) {
  const Motion& m = view.motion;
  end = std::min(end, m.frame_count);
  begin = std::min(begin, end);
  const std::size_t n = m.skeleton.size(), k = view.order.size();
  std::vector<Eigen::Vector3d> all(n), out((end - begin) * k);
  std::vector<Eigen::Matrix3d> orientations(view.viewer >= 0 ? n : 0);
  for (std::size_t f = begin; f < end; ++f) {
    view_frame(m, view.viewer, f, all, orientations);
    for (std::size_t i = 0; i < k; ++i) out[(f - begin) * k + i] = all[static_cast<std::size_t>(view.order[i])];
  }
  return out;
}

Skeleton view_names(const MotionView& view) {
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
