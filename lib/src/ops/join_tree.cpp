#include "gmr/ops/join_tree.h"

#include "steps.h"

namespace gmr {

using detail::Track;
using detail::Work;
using namespace detail;

Result<Motion> join_tree(const Motion& motion, int root, JoinReport* out_report) {
  if (Status st = check_pre(motion, "join"); !st) return st.error();
  if (Status st = check_joint(motion, root, "join"); !st) return st.error();
  const Skeleton& s = motion.skeleton;
  const std::string who = "cannot join " + quoted(s.joint(root).name) + ": ";
  if (!s.is_root(root)) return make_error(ErrorKind::kFailedPrecondition, who + "it is not a root");
  if (s.roots().size() == 1)
    return make_error(ErrorKind::kFailedPrecondition, who + "it is the last root of the skeleton");
  const int q = s.joint(root).soft_parent;
  if (q == kNoParent)
    return make_error(ErrorKind::kFailedPrecondition, who + "it has no soft link (it was not split from a parent)");
  if (s.root_of(q) == root) {
    return make_error(ErrorKind::kFailedPrecondition,
                      who + "its soft link " + quoted(s.joint(q).name) + " is in its own tree");
  }
  std::vector<JoinReport> reports;
  auto out = join_many(motion, {root}, &reports);
  if (out && out_report) *out_report = reports[0];
  return out;
}

}  // namespace gmr
