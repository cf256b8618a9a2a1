#include "gmr/ops/strip_dummies.h"

#include <cmath>

#include "steps.h"

namespace gmr {

using detail::Track;
using detail::Work;
using namespace detail;

Result<Motion> strip_dummies(const Motion& motion, std::vector<RemovedJoint>* out_removed) {
  if (Status st = check_pre(motion, "strip dummies"); !st) return st.error();
  Work w = Work::from_motion(motion);
  std::vector<RemovedJoint> removed;
  // Parents come first, so a chain of dummies collapses from the top.
  for (int d = 0; d < w.size(); ++d) {
    Track& t = w[d];
    if (t.parent == kNoParent || !t.pos_ch.empty() || t.offset != Eigen::Vector3d::Zero()) continue;
    const std::vector<int> kids = w.children(d);
    if (kids.empty()) continue;
    // [R_d | 0][R_c | R_c t_c] = [R_d R_c | R_d R_c t_c]: the child takes R_d R_c.
    for (int c : kids) {
      detail::set_product(w[c], w[d], false, w[c], w.frames);
      w[c].parent = t.parent;
    }
    t.removed = true;
    removed.push_back(RemovedJoint{t.name, w[t.parent].name});
  }
  auto out = w.to_motion();
  if (out && out_removed) *out_removed = std::move(removed);
  return out;
}

std::vector<std::string> constant_rotation_joints(const Motion& motion, double tolerance_degrees) {
  std::vector<std::string> out;
  if (motion.frame_count == 0 || !motion.validate()) return out;
  const Skeleton& s = motion.skeleton;
  // ||R - R0||_F = 2 sqrt(2) sin(theta / 2) for the angle theta of R0^T R.
  const double limit = 2.0 * std::sqrt(2.0) * std::sin(0.5 * tolerance_degrees * 3.14159265358979323846 / 180.0);
  for (int j = 0; j < static_cast<int>(s.size()); ++j) {
    if (!s.joint(j).has_rotation()) continue;
    const Eigen::Matrix3d r0 = motion.local_rotation(0, j);
    bool constant = true;
    for (std::size_t f = 1; f < motion.frame_count && constant; ++f) {
      constant = (motion.local_rotation(f, j) - r0).norm() <= limit;
    }
    if (constant) out.push_back(s.joint(j).name);
  }
  return out;
}

}  // namespace gmr
