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

  auto d = std::make_shared<Data>();
  d->joints = std::move(joints);
  d->channel_offsets.resize(static_cast<std::size_t>(n));
  d->depth.resize(static_cast<std::size_t>(n));
  d->root.resize(static_cast<std::size_t>(n));
  std::vector<int> child_count(static_cast<std::size_t>(n), 0);
  // Parents come before children, so one pass gives every depth and root.
  for (int j = 0; j < n; ++j) {
    const auto u = static_cast<std::size_t>(j);
    const Joint& joint = d->joints[u];
    d->channel_offsets[u] = d->channel_count;
    d->channel_count += static_cast<int>(joint.channels.size());
    if (joint.parent == kNoParent) {
      d->roots.push_back(j);
      d->depth[u] = 0;
      d->root[u] = j;
    } else {
      const auto p = static_cast<std::size_t>(joint.parent);
      ++child_count[p];
      d->depth[u] = d->depth[p] + 1;
      d->root[u] = d->root[p];
    }
  }
  d->child_begin.assign(static_cast<std::size_t>(n) + 1, 0);
  for (int j = 0; j < n; ++j) d->child_begin[j + 1] = d->child_begin[j] + child_count[j];
  d->child_list.resize(static_cast<std::size_t>(d->child_begin[n]));
  std::vector<int> fill(d->child_begin.begin(), d->child_begin.end() - 1);
  for (int j = 0; j < n; ++j) {
    const int p = d->joints[static_cast<std::size_t>(j)].parent;
    if (p != kNoParent) d->child_list[static_cast<std::size_t>(fill[p]++)] = j;
  }
  Skeleton s;
  s.data_ = std::move(d);
  return s;
}

const Skeleton::Data& Skeleton::empty_data() {
  static const Data empty;
  return empty;
}

int Skeleton::find(std::string_view name) const {
  const auto& joints = data().joints;
  for (std::size_t j = 0; j < joints.size(); ++j) {
    if (joints[j].name == name) return static_cast<int>(j);
  }
  return -1;
}

std::span<const int> Skeleton::children(int j) const {
  const Data& d = data();
  const auto b = static_cast<std::size_t>(d.child_begin[static_cast<std::size_t>(j)]);
  const auto e = static_cast<std::size_t>(d.child_begin[static_cast<std::size_t>(j) + 1]);
  return std::span<const int>(d.child_list).subspan(b, e - b);
}

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
