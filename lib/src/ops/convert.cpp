// BVH (post-rotation) <-> GMR (pre-rotation). The formulas are in docs/gmr-math.md.
//
// post: W_j = W_p S_j, P_j = P_p + W_p t_j      pre: W_j = W_p R_j, P_j = P_p + W_j t_j
//
// post -> pre: the pre frame of a non-root j must equal the post frame of its
// parent, so R_j = S_p(j) (a channel copy) and roots get R = I.
// pre -> post: the post frame of x must equal the pre frame of each child c, so
// S_x = R_c when all children share R_c (S_root = R_root R_c). When they do
// not, one group of children with equal rotation rides on x (S_x = R_main) and
// each other group hangs under a zero-length joint whose S is R_main^-1 R_group:
// a joint whose children fall into k groups gets k - 1 inserted joints, the
// fewest that can keep every position.
#include "gmr/ops/convert.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <string>

#include "work.h"

namespace gmr {
namespace {

using detail::Track;
using detail::Work;

// No rotation channel, or only angles that are whole turns in every frame.
bool is_identity(const Track& t) {
  for (double v : t.rot_v) {
    if (std::fmod(v, 360.0) != 0.0) return false;
  }
  return true;
}

bool same_rotation(const Track& a, const Track& b) {
  return (a.rot_ch == b.rot_ch && a.rot_v == b.rot_v) || (is_identity(a) && is_identity(b));
}

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

std::optional<PreRotationGather> PreRotationGather::make(const Skeleton& post) {
  Motion probe;
  probe.skeleton = post;
  probe.convention = Convention::kPostRotation;
  probe.frame_time = 1.0;
  probe.frame_count = 1;
  probe.values.resize(probe.stride());
  for (std::size_t k = 0; k < probe.values.size(); ++k) probe.values[k] = static_cast<double>(k + 1);
  auto pre = to_pre_rotation(probe);
  if (!pre.ok()) return std::nullopt;
  PreRotationGather g;
  g.skeleton_ = pre->skeleton;
  g.post_stride_ = probe.values.size();
  for (double v : pre->values) {
    if (v != std::floor(v) || v < 1.0 || v > static_cast<double>(probe.values.size())) return std::nullopt;
    g.from_.push_back(static_cast<std::size_t>(v) - 1);
  }
  return g;
}

Motion PreRotationGather::apply(std::span<const double> post, std::size_t frames, double frame_time) const {
  Motion out;
  out.skeleton = skeleton_;
  out.convention = Convention::kPreRotation;
  out.frame_time = frame_time;
  out.frame_count = frames;
  out.values.resize(frames * from_.size());
  for (std::size_t f = 0; f < frames && (f + 1) * post_stride_ <= post.size(); ++f) {
    const double* in = post.data() + f * post_stride_;
    double* to = out.values.data() + f * from_.size();
    for (std::size_t k = 0; k < from_.size(); ++k) to[k] = in[from_[k]];
  }
  return out;
}

Result<Motion> to_post_rotation(const Motion& motion) {
  if (Status s = motion.validate(); !s) return s.error();
  if (motion.convention == Convention::kPostRotation) return motion;
  const Work in = Work::from_motion(motion);
  const int n = in.size();
  const std::size_t frames = in.frames;

  std::vector<int> subtree(static_cast<std::size_t>(n), 1);  // joints in each subtree
  for (int j = 0; j < n; ++j) {
    for (int p = in[j].parent; p != kNoParent; p = in[p].parent) ++subtree[static_cast<std::size_t>(p)];
  }

  // For each child: the index of its group's first child when the group hangs
  // under an inserted joint, else -1.
  std::vector<int> group_head(static_cast<std::size_t>(n), -1);
  std::vector<Track> post(in.tracks);                        // S_x of every joint, parents as in `in`
  std::vector<Track> inserted(static_cast<std::size_t>(n));  // S of the joint inserted for a group, by its head
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
    if (heads.empty()) {
      if (!root) {
        s.rot_ch.clear();
        s.rot_v.clear();
      }
      continue;
    }
    // One group rides on x itself: S_x = R_main (roots: R_root R_main). The
    // group without rotation when there is one (the other groups' inserted
    // joints are then plain copies), else the largest subtree (first wins).
    int main = heads.front();
    std::size_t main_size = 0;
    for (int h : heads) {
      std::size_t size = 0;
      for (int c : kids) {
        if (group_head[static_cast<std::size_t>(c)] == h)
          size += static_cast<std::size_t>(subtree[static_cast<std::size_t>(c)]);
      }
      if (is_identity(in[h])) size = static_cast<std::size_t>(n) + 1;
      if (size > main_size) {
        main = h;
        main_size = size;
      }
    }
    const bool main_identity = is_identity(in[main]);
    if (root) {
      if (!main_identity) detail::set_product(s, in[x], false, in[main], frames);
    } else if (main_identity) {
      s.rot_ch.clear();
      s.rot_v.clear();
    } else {
      detail::copy_rotation(s, in[main]);
    }
    for (int c : kids) {
      const int h = group_head[static_cast<std::size_t>(c)];
      if (h == main) group_head[static_cast<std::size_t>(c)] = -1;
    }
    // Every other group hangs under a zero-length joint whose S turns x's
    // frame into the group's: R_main^-1 R_group (a copy when R_main = I).
    for (int h : heads) {
      if (h == main) continue;
      Track& d = inserted[static_cast<std::size_t>(h)];
      if (main_identity) {
        detail::copy_rotation(d, in[h]);
      } else {
        detail::set_product(d, in[main], true, is_identity(in[h]) ? Track{} : in[h], frames);
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
      detail::copy_rotation(d, inserted[static_cast<std::size_t>(j)]);
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

namespace {

// Rotation channels every BVH reader takes: none, or the three axes once each.
// One or two axes get the missing ones appended with zero angles (the same
// rotation); anything else (an axis twice, more than three) is re-encoded.
void three_rotation_axes(Track& t, std::size_t frames) {
  if (t.rot_ch.empty()) return;
  bool distinct = t.rot_ch.size() <= 3;
  for (std::size_t i = 0; i < t.rot_ch.size() && distinct; ++i) {
    for (std::size_t k = i + 1; k < t.rot_ch.size(); ++k) distinct = distinct && t.rot_ch[i] != t.rot_ch[k];
  }
  if (!distinct) {
    const std::vector<Eigen::Matrix3d> r = detail::rotations(t, frames);
    t.rot_ch.clear();
    detail::encode_rotations(t, r, frames);
    if (t.rot_ch.empty()) return;
  }
  const std::size_t k = t.rot_ch.size();
  if (k == 3) return;
  for (Axis a : {Axis::kX, Axis::kY, Axis::kZ}) {
    const ChannelType c = rotation_channel(a);
    if (std::find(t.rot_ch.begin(), t.rot_ch.end(), c) == t.rot_ch.end()) t.rot_ch.push_back(c);
  }
  std::vector<double> v(frames * 3, 0.0);
  for (std::size_t f = 0; f < frames; ++f) std::copy_n(t.rot_v.data() + f * k, k, v.data() + f * 3);
  t.rot_v = std::move(v);
}

// Position channels every BVH reader takes the same way: none, or all three
// with the OFFSET 0 (readers disagree on whether a channel adds to OFFSET or
// replaces it, and on what an axis without a channel means). A non-root joint
// whose channels never change gets them as its OFFSET instead.
void unambiguous_translation(Track& t, std::size_t frames, bool root) {
  if (t.pos_ch.empty()) return;
  std::vector<Eigen::Vector3d> v(frames);
  bool constant = true;
  for (std::size_t f = 0; f < frames; ++f) {
    v[f] = t.translation(f);
    constant = constant && v[f] == v[0];
  }
  if (!root && constant) {
    detail::set_translations(t, v, frames, false, t.offset);
    return;
  }
  detail::set_translations(t, v, frames, true, Eigen::Vector3d::Zero());
  t.offset = Eigen::Vector3d::Zero();
  // Assimp reads position channels only on a joint with six channels.
  if (t.rot_ch.empty()) {
    t.rot_ch = {ChannelType::kZrotation, ChannelType::kYrotation, ChannelType::kXrotation};
    t.rot_v.assign(frames * 3, 0.0);
  }
}

}  // namespace

Result<Motion> to_bvh_interchange(const Motion& motion, const BvhExportOptions& options) {
  Result<Motion> post = to_post_rotation(motion);
  if (!post) return post.error();
  Work w = Work::from_motion(*post);
  const std::size_t frames = w.frames;
  int roots = 0;
  for (const Track& t : w.tracks) roots += t.parent == kNoParent ? 1 : 0;
  if (options.single_root && roots > 1) {
    std::set<std::string> names;
    for (const Track& t : w.tracks) names.insert(t.name);
    std::string name = options.root_name;
    for (int k = 2; names.count(name) != 0; ++k) name = options.root_name + std::to_string(k);
    const int top = w.size();
    for (Track& t : w.tracks) {
      if (t.parent == kNoParent) t.parent = top;  // its translation is now its world position
    }
    Track world;
    world.name = std::move(name);
    w.tracks.push_back(std::move(world));
  }
  bool any_channel = false;
  for (Track& t : w.tracks) {
    t.soft_parent = kNoParent;  // BVH has no place for soft links
    three_rotation_axes(t, frames);
    unambiguous_translation(t, frames, t.parent == kNoParent);
    any_channel = any_channel || !t.rot_ch.empty() || !t.pos_ch.empty();
  }
  if (!any_channel && frames > 0) {
    // Rows with no value are blank lines, which readers skip: the frames would
    // be lost. The first root carries its position instead.
    for (Track& t : w.tracks) {
      if (t.parent != kNoParent) continue;
      t.pos_ch = {ChannelType::kXposition};  // made the full six by unambiguous_translation
      t.pos_v.assign(frames, t.offset.x());
      unambiguous_translation(t, frames, true);
      break;
    }
  }
  return w.to_motion();
}

Result<Motion> motion_from_world_poses(const std::vector<std::string>& names, const std::vector<int>& soft_parents,
                                       double frame_time, std::span<const Eigen::Vector3d> positions,
                                       std::span<const Eigen::Quaterniond> orientations) {
  const std::size_t n = names.size();
  if (soft_parents.size() != n) return make_error("one soft parent per joint is needed");
  if (n == 0 || positions.size() % n != 0) return make_error("positions must hold the same number of joints per frame");
  const std::size_t frames = positions.size() / n;
  if (!orientations.empty() && orientations.size() != positions.size()) {
    return make_error("orientations must be empty or one per position");
  }
  std::vector<Joint> joints(n);
  for (std::size_t j = 0; j < n; ++j) {
    joints[j].name = names[j];
    if (soft_parents[j] != kNoParent && (soft_parents[j] < 0 || static_cast<std::size_t>(soft_parents[j]) >= j)) {
      return make_error("joint '" + names[j] + "': its soft parent must come before it");
    }
    joints[j].soft_parent = soft_parents[j];
    joints[j].channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
    if (!orientations.empty()) {
      joints[j].channels.insert(joints[j].channels.end(),
                                {ChannelType::kZrotation, ChannelType::kXrotation, ChannelType::kYrotation});
    }
  }
  auto skeleton = Skeleton::create(std::move(joints));
  if (!skeleton) return skeleton.error();
  Motion m;
  m.skeleton = std::move(*skeleton);
  m.convention = Convention::kPreRotation;
  m.frame_time = frame_time;
  m.frame_count = frames;
  m.values.assign(frames * m.stride(), 0.0);
  static constexpr Axis kOrder[3] = {Axis::kZ, Axis::kX, Axis::kY};
  std::vector<Eigen::Vector3d> previous(n, Eigen::Vector3d::Zero());
  for (std::size_t f = 0; f < frames; ++f) {
    std::span<double> row = m.frame(f);
    std::size_t c = 0;
    for (std::size_t j = 0; j < n; ++j) {
      const Eigen::Vector3d& p = positions[f * n + j];
      row[c++] = p.x();
      row[c++] = p.y();
      row[c++] = p.z();
      if (orientations.empty()) continue;
      const Eigen::Matrix3d r = orientations[f * n + j].normalized().toRotationMatrix();
      const Eigen::Vector3d angles = decompose_euler(r, kOrder, f == 0 ? nullptr : &previous[j]);
      previous[j] = angles;
      for (int k = 0; k < 3; ++k) row[c++] = angles(k);
    }
  }
  if (auto s = m.validate(); !s) return s.error();
  return m;
}

}  // namespace gmr
