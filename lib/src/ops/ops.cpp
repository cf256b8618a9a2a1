// The GMR operations (paper 4.1), with the primes of ../shared/GMR-MATH.md.
// Every operation is computed for all frames and keeps every joint's world
// position. Splits and joins also keep every joint's world orientation W_j;
// a shift swaps the frames of the two joints it swaps (the root frame moves to
// the new root, the frame of bone J0-J1 moves to J0). docs/operations.md.
#include "gmr/ops/ops.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <set>
#include <string>

#include "gmr/kinematics/forward_kinematics.h"
#include "work.h"

namespace gmr {
namespace {

using detail::Track;
using detail::Work;

std::string quoted(const std::string& name) { return "'" + name + "'"; }

Status check_pre(const Motion& m, const char* op) {
  if (m.convention != Convention::kPreRotation) {
    return make_error(std::string(op) + " needs a pre-rotation (GMR) motion: convert it with to_pre_rotation first");
  }
  return m.validate();
}

Status check_joint(const Motion& m, int j, const char* op) {
  if (j < 0 || j >= static_cast<int>(m.skeleton.size())) {
    return make_error(std::string(op) + ": joint index " + std::to_string(j) + " out of range (skeleton has " +
                      std::to_string(m.skeleton.size()) + " joints)");
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

// Tree index of every joint (its root) in a motion.
std::vector<int> tree_of(const Skeleton& s) {
  std::vector<int> tree(s.size());
  for (int j = 0; j < static_cast<int>(s.size()); ++j) {
    tree[static_cast<std::size_t>(j)] = s.is_root(j) ? j : tree[static_cast<std::size_t>(s.joint(j).parent)];
  }
  return tree;
}

// Joins every root of `roots` under its soft parent in one pass (world
// transforms read from `motion`). Checks each join and that they form no cycle.
Result<Motion> join_many(const Motion& motion, const std::vector<int>& roots, std::vector<JoinReport>* out_reports) {
  const Skeleton& s = motion.skeleton;
  const std::vector<int> tree = tree_of(s);
  // Cycle check on trees: following soft links from a tree must end at a tree
  // that is not being joined.
  std::vector<int> link(s.size(), kNoParent);  // tree -> tree it joins into
  for (int r : roots) link[static_cast<std::size_t>(r)] = tree[static_cast<std::size_t>(s.joint(r).soft_parent)];
  for (int r : roots) {
    int t = r;
    for (std::size_t steps = 0; link[static_cast<std::size_t>(t)] != kNoParent; ++steps) {
      t = link[static_cast<std::size_t>(t)];
      if (t == r || steps > s.size()) {
        return make_error("cannot join " + quoted(s.joint(r).name) + ": soft links form a cycle (its soft link " +
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

Result<int> find_joint(const Skeleton& s, const std::string& name) {
  const int j = s.find(name);
  if (j < 0) return make_error("unknown joint " + quoted(name));
  return j;
}

}  // namespace

Result<Motion> shift_root(const Motion& motion, int joint) {
  if (Status st = check_pre(motion, "shift root"); !st) return st.error();
  if (Status st = check_joint(motion, joint, "shift root"); !st) return st.error();
  if (motion.skeleton.is_root(joint)) return motion;
  Work w = Work::from_motion(motion);
  std::vector<int> path;  // joint, parent, ..., root
  for (int j = joint; j != kNoParent; j = w[j].parent) path.push_back(j);
  for (std::size_t k = path.size() - 1; k > 0; --k) swap_root(w, path[k], path[k - 1]);
  return w.to_motion();
}

Result<Motion> split_tree(const Motion& motion, int joint) {
  if (Status st = check_pre(motion, "split"); !st) return st.error();
  if (Status st = check_joint(motion, joint, "split"); !st) return st.error();
  if (motion.skeleton.is_root(joint)) {
    return make_error("cannot split at " + quoted(motion.skeleton.joint(joint).name) + ": it is already a root");
  }
  return split_many(motion, {joint});
}

Result<Motion> join_tree(const Motion& motion, int root, JoinReport* out_report) {
  if (Status st = check_pre(motion, "join"); !st) return st.error();
  if (Status st = check_joint(motion, root, "join"); !st) return st.error();
  const Skeleton& s = motion.skeleton;
  const std::string who = "cannot join " + quoted(s.joint(root).name) + ": ";
  if (!s.is_root(root)) return make_error(who + "it is not a root");
  if (s.roots().size() == 1) return make_error(who + "it is the last root of the skeleton");
  const int q = s.joint(root).soft_parent;
  if (q == kNoParent) return make_error(who + "it has no soft link (it was not split from a parent)");
  if (s.root_of(q) == root) {
    return make_error(who + "its soft link " + quoted(s.joint(q).name) + " is in its own tree");
  }
  std::vector<JoinReport> reports;
  auto out = join_many(motion, {root}, &reports);
  if (out && out_report) *out_report = reports[0];
  return out;
}

Result<Motion> set_roots(const Motion& motion, std::span<const int> roots) {
  if (Status st = check_pre(motion, "set roots"); !st) return st.error();
  const Skeleton& s0 = motion.skeleton;
  const int n = static_cast<int>(s0.size());
  if (roots.empty()) return make_error("set roots: the set of roots is empty");
  std::vector<char> target(static_cast<std::size_t>(n), 0);
  std::vector<std::string> names;
  for (int r : roots) {
    if (Status st = check_joint(motion, r, "set roots"); !st) return st.error();
    if (target[static_cast<std::size_t>(r)]) return make_error("set roots: " + quoted(s0.joint(r).name) + " is listed twice");
    target[static_cast<std::size_t>(r)] = 1;
    names.push_back(s0.joint(r).name);
  }
  // Connected components over hard edges and soft links: each needs a root.
  std::vector<int> comp(static_cast<std::size_t>(n));
  std::iota(comp.begin(), comp.end(), 0);
  auto find = [&](int x) {
    while (comp[static_cast<std::size_t>(x)] != x) {
      auto& up = comp[static_cast<std::size_t>(x)];
      up = comp[static_cast<std::size_t>(up)];  // path halving
      x = up;
    }
    return x;
  };
  for (int j = 0; j < n; ++j) {
    const Joint& joint = s0.joint(j);
    const int other = joint.parent != kNoParent ? joint.parent : joint.soft_parent;
    if (other != kNoParent) comp[static_cast<std::size_t>(find(j))] = find(other);
  }
  std::vector<char> covered(static_cast<std::size_t>(n), 0);
  for (int r : roots) covered[static_cast<std::size_t>(find(r))] = 1;
  for (int j = 0; j < n; ++j) {
    if (!covered[static_cast<std::size_t>(find(j))]) {
      return make_error("set roots: no root given for the skeleton that holds " + quoted(s0.joint(j).name) +
                        " (each connected skeleton needs at least one)");
    }
  }

  // 1. Join every split tree back (one pass; world transforms are invariant).
  Motion m = motion;
  std::vector<int> linked;
  for (int r : s0.roots()) {
    if (s0.joint(r).soft_parent != kNoParent) linked.push_back(r);
  }
  if (!linked.empty()) {
    auto joined = join_many(m, linked, nullptr);
    if (!joined) return joined.error();
    m = std::move(joined).value();
  }
  // 2. In each tree, keep the root when it is a target, else move it to the
  // target nearest to it (ties: smallest name). Edge frames do not depend on
  // the rooting, so the result depends only on each tree's root and the set.
  std::vector<std::string> tree_targets;
  {
    const Skeleton& s = m.skeleton;
    std::vector<int> best(s.size(), -1);
    for (const std::string& name : names) {
      const int j = s.find(name);
      const auto r = static_cast<std::size_t>(s.root_of(j));
      const int b = best[r];
      if (b < 0 || s.depth(j) < s.depth(b) || (s.depth(j) == s.depth(b) && name < s.joint(b).name)) best[r] = j;
    }
    for (int r : s.roots()) {
      if (best[static_cast<std::size_t>(r)] >= 0) tree_targets.push_back(s.joint(best[static_cast<std::size_t>(r)]).name);
    }
  }
  for (const std::string& name : tree_targets) {
    auto shifted = shift_root(m, m.skeleton.find(name));
    if (!shifted) return shifted.error();
    m = std::move(shifted).value();
  }
  // 3. Split at every other target.
  std::vector<int> splits;
  for (const std::string& name : names) {
    const int j = m.skeleton.find(name);
    if (!m.skeleton.is_root(j)) splits.push_back(j);
  }
  if (splits.empty()) return m;
  return split_many(m, splits);
}

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

void intrinsic_positions(const Motion& motion, int viewer, std::size_t begin, std::size_t end,
                         std::vector<Eigen::Vector3d>& out_positions, std::vector<Eigen::Matrix3d>* out_orientations) {
  const std::size_t n = motion.skeleton.size();
  end = std::min(end, motion.frame_count);
  begin = std::min(begin, end);
  if (viewer < 0 || static_cast<std::size_t>(viewer) >= n) begin = end;
  out_positions.resize((end - begin) * n);
  if (out_orientations) out_orientations->resize((end - begin) * n);
  std::vector<Eigen::Vector3d> p(n);
  std::vector<Eigen::Matrix3d> o(n);
  const auto v = static_cast<std::size_t>(viewer);
  for (std::size_t f = begin; f < end; ++f) {
    compute_frame(motion, f, p, o);
    const Eigen::Matrix3d wt = o[v].transpose();
    const Eigen::Vector3d pv = p[v];
    for (std::size_t j = 0; j < n; ++j) {
      out_positions[(f - begin) * n + j] = wt * (p[j] - pv);
      if (out_orientations) (*out_orientations)[(f - begin) * n + j] = wt * o[j];
    }
  }
}

Result<std::vector<int>> find_joints(const Skeleton& skeleton, std::span<const std::string> names) {
  std::vector<int> out;
  for (const std::string& name : names) {
    auto j = find_joint(skeleton, name);
    if (!j) return j.error();
    out.push_back(*j);
  }
  return out;
}

}  // namespace gmr
