#include "gmr/ops/set_roots.h"

#include <algorithm>
#include <numeric>
#include <set>

#include "gmr/ops/shift_root.h"

#include "steps.h"

namespace gmr {

using detail::Track;
using detail::Work;
using namespace detail;

Result<Motion> set_roots(const Motion& motion, std::span<const int> roots) {
  if (Status st = check_pre(motion, "set roots"); !st) return st.error();
  const Skeleton& s0 = motion.skeleton;
  const int n = static_cast<int>(s0.size());
  if (roots.empty()) return make_error("set roots: the set of roots is empty");
  std::vector<char> target(static_cast<std::size_t>(n), 0);
  std::vector<std::string> names;
  for (int r : roots) {
    if (Status st = check_joint(motion, r, "set roots"); !st) return st.error();
    if (target[static_cast<std::size_t>(r)])
      return make_error("set roots: " + quoted(s0.joint(r).name) + " is listed twice");
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
      return make_error(ErrorKind::kFailedPrecondition, "set roots: no root given for the skeleton that holds " +
                                                            quoted(s0.joint(j).name) +
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
      if (best[static_cast<std::size_t>(r)] >= 0)
        tree_targets.push_back(s.joint(best[static_cast<std::size_t>(r)]).name);
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

}  // namespace gmr
