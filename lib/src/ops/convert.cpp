// BVH (post-rotation) <-> GMR (pre-rotation). The formulas are in docs/gmr-math.md.
//
// post: W_j = W_p S_j, P_j = P_p + W_p t_j      pre: W_j = W_p R_j, P_j = P_p + W_j t_j
//
// post -> pre: the pre frame of a non-root j must equal the post frame of its
// parent, so R_j = S_p(j) (a channel copy) and roots get R = I.
// pre -> post: the post frame of x must equal the pre frame of each child c, so
// S_x = R_c when all children share R_c (S_root = R_root R_c); when they do not,
// x gets S = I (roots: R_root) and each group of children with equal rotation
// hangs under a zero-length joint whose S is that rotation.
#include "gmr/ops/convert.h"

#include <set>
#include <string>

#include "work.h"

namespace gmr {
namespace {

using detail::Track;
using detail::Work;

bool same_rotation(const Track& a, const Track& b) { return a.rot_ch == b.rot_ch && a.rot_v == b.rot_v; }

}  // namespace

Result<Motion> to_pre_rotation(const Motion& motion) {
  if (Status s = motion.validate(); !s) return s.error();
  if (motion.convention == Convention::kPreRotation) return motion;
  const Work in = Work::from_motion(motion);
  Work out = in;
  out.convention = Convention::kPreRotation;
  for (int j = 0; j < in.size(); ++j) {
    const int p = in[j].parent;
    if (p == kNoParent) {
      out[j].rot_ch.clear();
      out[j].rot_v.clear();
    } else {
      detail::copy_rotation(out[j], in[p]);
    }
  }
  return out.to_motion();
}

Result<Motion> to_post_rotation(const Motion& motion) {
  if (Status s = motion.validate(); !s) return s.error();
  if (motion.convention == Convention::kPostRotation) return motion;
  const Work in = Work::from_motion(motion);
  const int n = in.size();
  const std::size_t frames = in.frames;

  // For each child: the index of its group's first child when the group hangs
  // under an inserted joint, else -1.
  std::vector<int> group_head(static_cast<std::size_t>(n), -1);
  std::vector<Track> post(in.tracks);  // S_x of every joint, parents as in `in`
  for (int x = 0; x < n; ++x) {
    const std::vector<int> kids = in.children(x);
    std::vector<int> heads;  // first child of each group of equal rotations
    for (int c : kids) {
      int head = -1;
      for (int h : heads) {
        if (same_rotation(in[h], in[c])) head = h;
      }
      if (head < 0) heads.push_back(c);
      group_head[static_cast<std::size_t>(c)] = head < 0 ? c : head;
    }
    Track& s = post[static_cast<std::size_t>(x)];
    const bool root = in[x].parent == kNoParent;
    if (heads.size() == 1) {
      // One shared rotation: S_x = R_c (roots: R_root R_c); no inserted joint.
      const Track& shared = in[heads[0]];
      if (root) {
        detail::set_product(s, in[x], false, shared, frames);
      } else {
        detail::copy_rotation(s, shared);
      }
      for (int c : kids) group_head[static_cast<std::size_t>(c)] = -1;
    } else {
      // No child, or children that rotate independently: S_x = I (roots keep R_root).
      if (!root) {
        s.rot_ch.clear();
        s.rot_v.clear();
      }
      for (int c : kids) {
        // Children without rotation need no inserted joint.
        if (!in[c].has_rotation()) group_head[static_cast<std::size_t>(c)] = -1;
      }
    }
  }

  std::set<std::string> names;
  for (const Track& t : in.tracks) names.insert(t.name);
  Work out;
  out.frames = frames;
  out.frame_time = in.frame_time;
  out.convention = Convention::kPostRotation;
  std::vector<int> new_index(static_cast<std::size_t>(n), kNoParent);
  std::vector<int> dummy_index(static_cast<std::size_t>(n), kNoParent);  // by group head
  for (int j = 0; j < n; ++j) {
    const int head = group_head[static_cast<std::size_t>(j)];
    const int p = in[j].parent;
    if (head == j) {
      // Insert the zero-length joint just before the group's first child.
      Track d;
      std::string name = in[j].name + "_gmr_pre";
      for (int k = 2; names.count(name) != 0; ++k) name = in[j].name + "_gmr_pre" + std::to_string(k);
      names.insert(name);
      d.name = std::move(name);
      d.parent = new_index[static_cast<std::size_t>(p)];
      detail::copy_rotation(d, in[j]);
      dummy_index[static_cast<std::size_t>(j)] = out.size();
      out.tracks.push_back(std::move(d));
    }
    Track t = post[static_cast<std::size_t>(j)];
    if (head >= 0) {
      t.parent = dummy_index[static_cast<std::size_t>(head)];
    } else if (p != kNoParent) {
      t.parent = new_index[static_cast<std::size_t>(p)];
    }
    if (t.soft_parent != kNoParent) t.soft_parent = -2 - t.soft_parent;  // remapped below
    new_index[static_cast<std::size_t>(j)] = out.size();
    out.tracks.push_back(std::move(t));
  }
  for (Track& t : out.tracks) {
    if (t.soft_parent <= -2) t.soft_parent = new_index[static_cast<std::size_t>(-2 - t.soft_parent)];
  }
  return out.to_motion();
}

}  // namespace gmr
