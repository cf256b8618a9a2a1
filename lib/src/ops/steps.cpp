// The steps of the GMR operations (paper 4.1, primes restored in
// docs/gmr-math.md). Every step is computed for all frames and keeps every
// joint's world position. Splits and joins also keep every joint's world
// orientation W_j; a shift swaps the frames of the two joints it swaps (the
// root frame moves to the new root, the frame of bone J0-J1 moves to J0).
// docs/operations.md.
#include "steps.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <set>
#include <string>

#include "gmr/kinematics/forward_kinematics.h"

namespace gmr::detail {

std::string quoted(const std::string& name) { return "'" + name + "'"; }

Status check_pre(const Motion& m, const char* op) {
  if (m.convention != Convention::kPreRotation) {
    return make_error(ErrorKind::kFailedPrecondition,
                      std::string(op) + " needs a pre-rotation (GMR) motion: convert it with to_pre_rotation first");
  }
  return m.validate();
}

Status check_joint(const Motion& m, int j, const char* op) {
  if (j < 0 || j >= static_cast<int>(m.skeleton.size())) {
    return make_error(ErrorKind::kNotFound, std::string(op) + ": joint index " + std::to_string(j) +
                                                " out of range (skeleton has " + std::to_string(m.skeleton.size()) +
                                                " joints)");
  }
  return Ok{};
}

// Paper 4.1.1: swaps root j0 with its child j1.
//   g' = g + R0 R1 t1;  R1' = R0, t1' = 0 (new root);  R0' = R1, t0' = -t1;
//   J0's other children: R' = R1^-1 R;  J1's children: R' = R1 R.
void swap_root(Work& w, int j0, int j1) {
  const std::size_t frames = w.frames;
  const Track a = w[j0];
  const Track b = w[j1];
  const std::vector<int> kids0 = w.children(j0);
  const std::vector<int> kids1 = w.children(j1);

  std::vector<Eigen::Vector3d> g(frames);
  for (std::size_t f = 0; f < frames; ++f) {
    g[f] = a.translation(f) + a.rotation(f) * (b.rotation(f) * b.translation(f));
  }
  for (int c : kids0) {
    if (c != j1) detail::set_product(w[c], b, true, w[c], frames);
  }
  for (int c : kids1) detail::set_product(w[c], b, false, w[c], frames);

  Track& nb = w[j1];
  nb.parent = kNoParent;
  nb.soft_parent = a.soft_parent;  // the tree's soft link moves with its root
  detail::copy_rotation(nb, a);
  detail::set_translations(nb, g, frames, /*force_channels=*/true, a.offset);

  Track& na = w[j0];
  na.parent = j1;
  na.soft_parent = kNoParent;
  detail::copy_rotation(na, b);
  // t0' = -t1: a negated copy, so a static offset stays static.
  na.offset = -b.offset;
  na.pos_ch = b.pos_ch;
  na.pos_v = b.pos_v;
  for (double& v : na.pos_v) v = -v;
}

// Splits every joint of `joints` (non-roots) in one pass. World transforms are
// read from `motion`, which all splits leave unchanged.
Result<Motion> split_many(const Motion& motion, const std::vector<int>& joints) {
  Work w = Work::from_motion(motion);
  const std::size_t frames = w.frames, n = motion.skeleton.size();
  std::vector<std::vector<Eigen::Matrix3d>> rot(joints.size(), std::vector<Eigen::Matrix3d>(frames));
  std::vector<std::vector<Eigen::Vector3d>> pos(joints.size(), std::vector<Eigen::Vector3d>(frames));
  std::vector<Eigen::Vector3d> p(n);
  std::vector<Eigen::Matrix3d> o(n);
  for (std::size_t f = 0; f < frames; ++f) {
    compute_frame(motion, f, p, o);
    for (std::size_t k = 0; k < joints.size(); ++k) {
      rot[k][f] = o[static_cast<std::size_t>(joints[k])];
      pos[k][f] = p[static_cast<std::size_t>(joints[k])];
    }
  }
  for (std::size_t k = 0; k < joints.size(); ++k) {
    const int j = joints[k];
    Track& t = w[j];
    const std::vector<ChannelType> parent_order = w[t.parent].rot_ch;
    t.soft_parent = t.parent;
    t.parent = kNoParent;
    detail::encode_rotations(t, rot[k], frames, parent_order);
    detail::set_translations(t, pos[k], frames, /*force_channels=*/true, t.offset);
  }
  return w.to_motion();
}

// Joins every root of `roots` under its soft parent in one pass (world
// transforms read from `motion`). Checks each join and that they form no cycle.
Result<Motion> join_many(const Motion& motion, const std::vector<int>& roots, std::vector<JoinReport>* out_reports) {
  const Skeleton& s = motion.skeleton;
  // Cycle check on trees: following soft links from a tree must end at a tree
  // that is not being joined.
  std::vector<int> link(s.size(), kNoParent);  // tree -> tree it joins into
  for (int r : roots) link[static_cast<std::size_t>(r)] = s.root_of(s.joint(r).soft_parent);
  for (int r : roots) {
    int t = r;
    for (std::size_t steps = 0; link[static_cast<std::size_t>(t)] != kNoParent; ++steps) {
      t = link[static_cast<std::size_t>(t)];
      if (t == r || steps > s.size()) {
        return make_error(ErrorKind::kFailedPrecondition,
                          "cannot join " + quoted(s.joint(r).name) + ": soft links form a cycle (its soft link " +
                              quoted(s.joint(s.joint(r).soft_parent).name) + " is in its own tree after the joins)");
      }
    }
  }

  Work w = Work::from_motion(motion);
  const std::size_t frames = w.frames, n = s.size();
  const double tol = 1e-9 * skeleton_size(motion);
  std::vector<std::vector<Eigen::Matrix3d>> rot(roots.size(), std::vector<Eigen::Matrix3d>(frames));
  std::vector<std::vector<Eigen::Vector3d>> off(roots.size(), std::vector<Eigen::Vector3d>(frames));
  std::vector<Eigen::Vector3d> p(n);
  std::vector<Eigen::Matrix3d> o(n);
  for (std::size_t f = 0; f < frames; ++f) {
    compute_frame(motion, f, p, o);
    for (std::size_t k = 0; k < roots.size(); ++k) {
      const auto r = static_cast<std::size_t>(roots[k]);
      const auto q = static_cast<std::size_t>(s.joint(roots[k]).soft_parent);
      // R1 = Rp^-1 Rs, t1 = Rs^-1 (ts - tp)
      rot[k][f] = o[q].transpose() * o[r];
      off[k][f] = o[r].transpose() * (p[r] - p[q]);
    }
  }
  if (out_reports) out_reports->assign(roots.size(), JoinReport{});
  for (std::size_t k = 0; k < roots.size(); ++k) {
    Track& t = w[roots[k]];
    const int q = t.soft_parent;
    const std::vector<ChannelType> parent_order = w[q].rot_ch;
    t.parent = q;
    t.soft_parent = kNoParent;
    detail::encode_rotations(t, rot[k], frames, parent_order);
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& v : off[k]) mean += v;
    if (frames > 0) mean /= static_cast<double>(frames);
    double spread = 0.0;
    for (const auto& v : off[k]) spread = std::max(spread, (v - mean).norm());
    JoinReport report;
    report.offset_spread = spread;
    if (frames == 0 || spread <= tol) {
      // Rigid: the recovered offset is static again (as before the split).
      t.pos_ch.clear();
      t.pos_v.clear();
      t.offset = frames == 0 ? Eigen::Vector3d::Zero() : mean;
    } else {
      // Moved on its own: keep exact positions with per-frame translation channels.
      detail::set_translations(t, off[k], frames, /*force_channels=*/true, mean);
      report.translation_channels = true;
    }
    if (out_reports) (*out_reports)[k] = report;
  }
  return w.to_motion();
}

}  // namespace gmr::detail
