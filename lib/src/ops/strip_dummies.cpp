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
  const int n = w.size();
  const auto at = [](int j) { return static_cast<std::size_t>(j); };
  // A zero-length bone joins j to its parent: positions equal in every frame.
  auto zero_bone = [&](int j) {
    const Track& t = w[j];
    return t.parent != kNoParent && t.pos_ch.empty() && t.offset == Eigen::Vector3d::Zero();
  };
  // Bones at each joint, parent and children alike: the same wherever the roots are.
  std::vector<int> bones(at(n), 0);
  for (int j = 0; j < n; ++j) {
    if (w[j].parent == kNoParent) continue;
    ++bones[at(j)];
    ++bones[at(w[j].parent)];
  }
  // The top of j's group: its highest ancestor through zero-length bones.
  std::vector<int> top(at(n), -1);
  for (int j = 0; j < n; ++j) {
    std::vector<int> path;
    int k = j;
    while (top[at(k)] < 0 && zero_bone(k)) {
      path.push_back(k);
      k = w[k].parent;
    }
    const int t = top[at(k)] < 0 ? k : top[at(k)];
    top[at(k)] = t;
    for (int p : path) top[at(p)] = t;
  }
  // The member whose name the group keeps.
  std::vector<int> keeper(at(n), -1);
  for (int j = 0; j < n; ++j) {
    int& k = keeper[at(top[at(j)])];
    if (k < 0 || bones[at(j)] > bones[at(k)] || (bones[at(j)] == bones[at(k)] && w[j].name < w[k].name)) k = j;
  }
  std::vector<std::string> names(at(n));
  for (int j = 0; j < n; ++j) names[at(j)] = w[j].name;

  std::vector<RemovedJoint> removed;
  // Every member but the top goes, parents first, so a chain collapses from
  // the top: [R_d | 0][R_c | R_c t_c] = [R_d R_c | R_d R_c t_c].
  std::vector<bool> done(at(n), false);
  std::vector<int> order;
  for (int j = 0; j < n; ++j) {
    std::vector<int> chain;
    for (int k = j; k != kNoParent && !done[at(k)]; k = w[k].parent) chain.push_back(k);
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
      done[at(*it)] = true;
      order.push_back(*it);
    }
  }
  for (int d : order) {
    if (top[at(d)] == d) continue;
    for (int c : w.children(d)) {
      detail::set_product(w[c], w[d], false, w[c], w.frames);
      w[c].parent = w[d].parent;
    }
    w[d].removed = true;
  }
  for (int j = 0; j < n; ++j) {
    const int k = keeper[at(top[at(j)])];
    if (j != k) removed.push_back(RemovedJoint{names[at(j)], names[at(k)]});
    if (top[at(j)] == j) w[j].name = names[at(k)];
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
