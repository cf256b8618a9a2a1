#include "work.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <queue>

namespace gmr::detail {
namespace {

// Angles within this of a multiple of 360 degrees count as zero when deciding
// whether an added Euler axis can be dropped: 1e-10 degrees moves a point at
// distance d by 2e-12 d, far below any tolerance the operations promise.
constexpr double kZeroAngleDegrees = 1e-10;
// A rotation this close to identity (largest entry of R - I) is stored as no
// rotation channels at all; the same argument as above.
constexpr double kIdentityTolerance = 1e-14;

std::vector<Axis> axes_of(std::span<const ChannelType> ch) {
  std::vector<Axis> out;
  for (ChannelType c : ch) {
    if (is_rotation(c)) out.push_back(axis_of(c));
  }
  return out;
}

bool near_zero_turn(double deg) { return std::abs(deg - 360.0 * std::round(deg / 360.0)) <= kZeroAngleDegrees; }

}  // namespace

Eigen::Matrix3d Track::rotation(std::size_t f) const {
  const std::size_t k = rot_ch.size();
  if (k == 0) return Eigen::Matrix3d::Identity();
  return compose_rotation(rot_ch, std::span<const double>(rot_v).subspan(f * k, k));
}

Eigen::Vector3d Track::translation(std::size_t f) const {
  Eigen::Vector3d t = offset;
  const std::size_t k = pos_ch.size();
  for (std::size_t i = 0; i < k; ++i) t[static_cast<int>(axis_of(pos_ch[i]))] = pos_v[f * k + i];
  return t;
}

Work Work::from_motion(const Motion& m) {
  Work w;
  w.frames = m.frame_count;
  w.frame_time = m.frame_time;
  w.convention = m.convention;
  const Skeleton& s = m.skeleton;
  w.tracks.resize(s.size());
  for (int j = 0; j < static_cast<int>(s.size()); ++j) {
    const Joint& joint = s.joint(j);
    Track& t = w[j];
    t.name = joint.name;
    t.parent = joint.parent;
    t.soft_parent = joint.soft_parent;
    t.offset = joint.offset;
    std::vector<std::size_t> pos_idx, rot_idx;
    for (std::size_t i = 0; i < joint.channels.size(); ++i) {
      if (is_position(joint.channels[i])) {
        t.pos_ch.push_back(joint.channels[i]);
        pos_idx.push_back(i);
      } else {
        t.rot_ch.push_back(joint.channels[i]);
        rot_idx.push_back(i);
      }
    }
    t.pos_v.resize(w.frames * pos_idx.size());
    t.rot_v.resize(w.frames * rot_idx.size());
    for (std::size_t f = 0; f < w.frames; ++f) {
      const auto v = m.joint_values(f, j);
      for (std::size_t i = 0; i < pos_idx.size(); ++i) t.pos_v[f * pos_idx.size() + i] = v[pos_idx[i]];
      for (std::size_t i = 0; i < rot_idx.size(); ++i) t.rot_v[f * rot_idx.size() + i] = v[rot_idx[i]];
    }
  }
  return w;
}

std::vector<int> Work::children(int j) const {
  std::vector<int> out;
  for (int c = 0; c < size(); ++c) {
    if (!(*this)[c].removed && (*this)[c].parent == j) out.push_back(c);
  }
  return out;
}

Result<Motion> Work::to_motion() const {
  const int n = size();
  // Nearest kept ancestor (or self) of each joint, for parents and soft links.
  auto kept = [&](int j) {
    while (j != kNoParent && (*this)[j].removed) j = (*this)[j].parent;
    return j;
  };
  std::vector<int> parent(static_cast<std::size_t>(n), kNoParent);
  std::vector<std::vector<int>> kids(static_cast<std::size_t>(n));
  for (int j = 0; j < n; ++j) {
    if ((*this)[j].removed) continue;
    const int p = kept((*this)[j].parent);
    parent[static_cast<std::size_t>(j)] = p;
    if (p != kNoParent) kids[static_cast<std::size_t>(p)].push_back(j);
  }
  // Stable topological order: among joints whose parent is placed, lowest index first.
  std::priority_queue<int, std::vector<int>, std::greater<>> ready;
  for (int j = 0; j < n; ++j) {
    if (!(*this)[j].removed && parent[static_cast<std::size_t>(j)] == kNoParent) ready.push(j);
  }
  std::vector<int> order;
  std::vector<int> new_index(static_cast<std::size_t>(n), kNoParent);
  while (!ready.empty()) {
    const int j = ready.top();
    ready.pop();
    new_index[static_cast<std::size_t>(j)] = static_cast<int>(order.size());
    order.push_back(j);
    for (int c : kids[static_cast<std::size_t>(j)]) ready.push(c);
  }
  std::size_t kept_count = 0;
  for (int j = 0; j < n; ++j) kept_count += (*this)[j].removed ? 0 : 1;
  if (order.size() != kept_count) return make_error("the joints' parent links form a cycle");

  std::vector<Joint> joints;
  joints.reserve(order.size());
  for (int j : order) {
    const Track& t = (*this)[j];
    Joint joint;
    joint.name = t.name;
    const int p = parent[static_cast<std::size_t>(j)];
    joint.parent = p == kNoParent ? kNoParent : new_index[static_cast<std::size_t>(p)];
    if (joint.parent == kNoParent) {
      const int sp = kept(t.soft_parent);
      joint.soft_parent = sp == kNoParent ? kNoParent : new_index[static_cast<std::size_t>(sp)];
    }
    joint.offset = t.offset;
    joint.channels = t.pos_ch;
    joint.channels.insert(joint.channels.end(), t.rot_ch.begin(), t.rot_ch.end());
    joints.push_back(std::move(joint));
  }
  auto skeleton = Skeleton::create(std::move(joints));
  if (!skeleton) return skeleton.error();

  Motion m;
  m.skeleton = std::move(skeleton).value();
  m.convention = convention;
  m.frame_time = frame_time;
  m.frame_count = frames;
  const std::size_t stride = m.stride();
  m.values.resize(frames * stride);
  for (std::size_t k = 0; k < order.size(); ++k) {
    const Track& t = (*this)[order[k]];
    const auto base = static_cast<std::size_t>(m.skeleton.channel_offset(static_cast<int>(k)));
    const std::size_t np = t.pos_ch.size(), nr = t.rot_ch.size();
    for (std::size_t f = 0; f < frames; ++f) {
      double* row = m.values.data() + f * stride + base;
      std::copy_n(t.pos_v.data() + f * np, np, row);
      std::copy_n(t.rot_v.data() + f * nr, nr, row + np);
    }
  }
  return m;
}

std::vector<Eigen::Matrix3d> rotations(const Track& t, std::size_t frames) {
  std::vector<Eigen::Matrix3d> out(frames);
  for (std::size_t f = 0; f < frames; ++f) out[f] = t.rotation(f);
  return out;
}

void encode_rotations(Track& t, std::span<const Eigen::Matrix3d> r, std::size_t frames,
                      std::span<const ChannelType> fallback) {
  if (frames == 0) {  // nothing to encode: keep (or adopt) the channel layout
    if (t.rot_ch.empty()) t.rot_ch.assign(fallback.begin(), fallback.end());
    t.rot_v.clear();
    return;
  }
  bool identity = true;
  for (std::size_t f = 0; f < frames && identity; ++f) {
    identity = (r[f] - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <= kIdentityTolerance;
  }
  if (identity) {
    t.rot_ch.clear();
    t.rot_v.clear();
    return;
  }
  std::vector<Axis> order = axes_of(t.rot_ch);
  const std::size_t own = order.size();
  if (own == 0) {
    order = axes_of(fallback);
    if (order.size() != 3) order = {Axis::kZ, Axis::kX, Axis::kY};
  } else {
    for (Axis a : {Axis::kX, Axis::kY, Axis::kZ}) {
      if (std::find(order.begin(), order.end(), a) == order.end()) order.push_back(a);
    }
  }
  std::vector<double> v(frames * 3);
  Eigen::Vector3d prev;
  // Continuity: start from the joint's own angles when the order is unchanged.
  const bool same_order = own == 3 && t.rot_ch.size() == 3;
  for (std::size_t f = 0; f < frames; ++f) {
    const Eigen::Vector3d* hint = nullptr;
    Eigen::Vector3d first;
    if (f > 0) {
      hint = &prev;
    } else if (same_order) {
      first = Eigen::Vector3d(t.rot_v[0], t.rot_v[1], t.rot_v[2]);
      hint = &first;
    }
    prev = decompose_euler(r[f], order.data(), hint);
    v[f * 3 + 0] = prev[0];
    v[f * 3 + 1] = prev[1];
    v[f * 3 + 2] = prev[2];
  }
  // Drop trailing added axes that are zero in every frame (a joint with one or
  // two axes keeps them when the product stays within them).
  std::size_t keep = 3;
  const std::size_t min_keep = own == 0 ? 3 : own;
  while (keep > min_keep) {
    bool zero = true;
    for (std::size_t f = 0; f < frames && zero; ++f) zero = near_zero_turn(v[f * 3 + keep - 1]);
    if (!zero) break;
    --keep;
  }
  t.rot_ch.clear();
  for (std::size_t i = 0; i < keep; ++i) t.rot_ch.push_back(rotation_channel(order[i]));
  t.rot_v.resize(frames * keep);
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t i = 0; i < keep; ++i) t.rot_v[f * keep + i] = v[f * 3 + i];
  }
}

void copy_rotation(Track& to, const Track& from) {
  if (&to == &from) return;
  to.rot_ch = from.rot_ch;
  to.rot_v = from.rot_v;
}

void set_product(Track& out, const Track& a, bool inv_a, const Track& b, std::size_t frames) {
  if (!a.has_rotation()) {
    copy_rotation(out, b);
    return;
  }
  if (!b.has_rotation() && !inv_a) {
    copy_rotation(out, a);
    return;
  }
  std::vector<Eigen::Matrix3d> r(frames);
  for (std::size_t f = 0; f < frames; ++f) {
    const Eigen::Matrix3d ra = a.rotation(f);
    r[f] = (inv_a ? Eigen::Matrix3d(ra.transpose()) : ra) * b.rotation(f);
  }
  // Fallback order for a joint that had no rotation: the non-identity factor's.
  const std::vector<ChannelType> fallback = b.has_rotation() ? b.rot_ch : a.rot_ch;
  encode_rotations(out, r, frames, fallback);
}

void set_translations(Track& t, std::span<const Eigen::Vector3d> v, std::size_t frames, bool force_channels,
                      const Eigen::Vector3d& static_value) {
  bool constant = true;
  for (std::size_t f = 1; f < frames && constant; ++f) constant = v[f] == v[0];
  t.offset = frames == 0 ? static_value : v[0];
  if (!force_channels && constant) {
    t.pos_ch.clear();
    t.pos_v.clear();
    return;
  }
  t.pos_ch = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
  t.pos_v.resize(frames * 3);
  for (std::size_t f = 0; f < frames; ++f) {
    t.pos_v[f * 3 + 0] = v[f].x();
    t.pos_v[f * 3 + 1] = v[f].y();
    t.pos_v[f * 3 + 2] = v[f].z();
  }
}

}  // namespace gmr::detail
