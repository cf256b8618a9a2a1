#include "gmr/ops/split_tree.h"

#include "steps.h"

namespace gmr {

using detail::Track;
using detail::Work;
using namespace detail;

Result<Motion> split_tree(const Motion& motion, int joint) {
  if (Status st = check_pre(motion, "split"); !st) return st.error();
  if (Status st = check_joint(motion, joint, "split"); !st) return st.error();
  if (motion.skeleton.is_root(joint)) {
    return make_error(ErrorKind::kFailedPrecondition,
                      "cannot split at " + quoted(motion.skeleton.joint(joint).name) + ": it is already a root");
  }
  return split_many(motion, {joint});
}

}  // namespace gmr
