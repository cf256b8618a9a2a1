#include "gmr/ops/shift_root.h"

#include "steps.h"

namespace gmr {

using detail::Track;
using detail::Work;
using namespace detail;

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

}  // namespace gmr
