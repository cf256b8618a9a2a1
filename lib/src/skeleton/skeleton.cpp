#include "gmr/skeleton/skeleton.h"

#include <algorithm>
#include <unordered_set>

namespace gmr {

bool Joint::has_rotation() const {
  return std::any_of(channels.begin(), channels.end(), [](ChannelType c) { return is_rotation(c); });
}

bool Joint::has_translation() const {
  return std::any_of(channels.begin(), channels.end(), [](ChannelType c) { return is_position(c); });
}

Result<Skeleton> Skeleton::create(std::vector<Joint> joints) {
  const int n = static_cast<int>(joints.size());
  std::unordered_set<std::string_view> names;
  for (int j = 0; j < n; ++j) {
    const Joint& joint = joints[static_cast<std::size_t>(j)];
    const std::string who = "joint " + std::to_string(j) + " '" + joint.name + "'";
    if (joint.name.empty()) return make_error("joint " + std::to_string(j) + " has an empty name");
    if (!names.insert(joint.name).second) return make_error("duplicate joint name '" + joint.name + "'");
    if (joint.parent != kNoParent && (joint.parent < 0 || joint.parent >= n))
      return make_error(who + ": parent index " + std::to_string(joint.parent) + " out of range");
    if (joint.parent != kNoParent && joint.parent >= j) return make_error(who + ": parent must come before its child");
    if (joint.soft_parent != kNoParent) {
      if (joint.parent != kNoParent) return make_error(who + ": only a root may have a soft link");
      if (joint.soft_parent < 0 || joint.soft_parent >= n || joint.soft_parent == j)
        return make_error(who + ": soft link index " + std::to_string(joint.soft_parent) + " out of range");
    }
    if (!joint.offset.allFinite()) return make_error(who + ": offset is not finite");
    unsigned seen = 0;
    for (ChannelType c : joint.channels) {
      const unsigned bit = 1u << static_cast<unsigned>(c);
      if (seen & bit) return make_error(who + ": channel " + std::string(channel_name(c)) + " listed twice");
      seen |= bit;
    }
  }

  Skeleton s;
  s.joints_ = std::move(joints);
  s.channel_offsets_.resize(static_cast<std::size_t>(n));
  s.depth_.resize(static_cast<std::size_t>(n));
  s.root_.resize(static_cast<std::size_t>(n));
  std::vector<int> child_count(static_cast<std::size_t>(n), 0);
  // Parents come before children, so one pass gives every depth and root.
  for (int j = 0; j < n; ++j) {
    const auto u = static_cast<std::size_t>(j);
    const Joint& joint = s.joints_[u];
    s.channel_offsets_[u] = s.channel_count_;
    s.channel_count_ += static_cast<int>(joint.channels.size());
    if (joint.parent == kNoParent) {
      s.roots_.push_back(j);
      s.depth_[u] = 0;
      s.root_[u] = j;
    } else {
      const auto p = static_cast<std::size_t>(joint.parent);
      ++child_count[p];
      s.depth_[u] = s.depth_[p] + 1;
      s.root_[u] = s.root_[p];
    }
  }
  s.child_begin_.assign(static_cast<std::size_t>(n) + 1, 0);
  for (int j = 0; j < n; ++j) s.child_begin_[j + 1] = s.child_begin_[j] + child_count[j];
  s.child_list_.resize(static_cast<std::size_t>(s.child_begin_[n]));
  std::vector<int> fill(s.child_begin_.begin(), s.child_begin_.end() - 1);
  for (int j = 0; j < n; ++j) {
    const int p = s.joints_[static_cast<std::size_t>(j)].parent;
    if (p != kNoParent) s.child_list_[static_cast<std::size_t>(fill[p]++)] = j;
  }
  return s;
}

int Skeleton::find(std::string_view name) const {
  for (std::size_t j = 0; j < joints_.size(); ++j) {
    if (joints_[j].name == name) return static_cast<int>(j);
  }
  return -1;
}

std::span<const int> Skeleton::children(int j) const {
  const auto b = static_cast<std::size_t>(child_begin_[j]);
  const auto e = static_cast<std::size_t>(child_begin_[j + 1]);
  return std::span<const int>(child_list_).subspan(b, e - b);
}

int Skeleton::root_of(int j) const { return root_[static_cast<std::size_t>(j)]; }

int Skeleton::depth(int j) const { return depth_[static_cast<std::size_t>(j)]; }

Result<std::vector<int>> find_joints(const Skeleton& skeleton, std::span<const std::string> names) {
  std::vector<int> out;
  out.reserve(names.size());
  for (const std::string& name : names) {
    const int j = skeleton.find(name);
    if (j < 0) return make_error(ErrorKind::kNotFound, "unknown joint '" + name + "'");
    out.push_back(j);
  }
  return out;
}

}  // namespace gmr
