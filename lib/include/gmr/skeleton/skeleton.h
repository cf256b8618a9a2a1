// The skeleton: a forest of joints.
//
//        Hips (root)               Neck (root, soft link -> Spine)
//       /    |                     /    |     |
//   LHip   Spine               Head LShoulder RShoulder
//
// Any joint may be a root and there may be several roots. A root that a split
// created keeps a "soft link" to the parent it had, so a join can undo it.
// Joints are stored so that every parent comes before its children (index of
// parent < index of child); forward kinematics is then one pass in index order.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/core/rotation.h"

namespace gmr {

inline constexpr int kNoParent = -1;

struct Joint {
  std::string name;                                  // unique in the skeleton, non-empty
  int parent = kNoParent;                            // kNoParent for a root
  int soft_parent = kNoParent;                       // roots only: the parent a split removed
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();  // static offset from the parent (roots: position)
  std::vector<ChannelType> channels;                 // listed order; rotations compose in this order

  bool has_rotation() const;
  bool has_translation() const;
};

// A validated forest. Build with Skeleton::create(); joints cannot be edited in
// place (take joints(), edit the copy, create() again).
class Skeleton {
 public:
  Skeleton() = default;

  // Checks and indexes `joints`. Fails (naming the rule and the joint) when: a
  // name is empty or repeated; a parent or soft parent is out of range; a parent
  // does not come before its child; a non-root has a soft parent; a joint lists
  // the same channel twice.
  static Result<Skeleton> create(std::vector<Joint> joints);

  std::size_t size() const { return data().joints.size(); }
  bool empty() const { return data().joints.empty(); }
  const std::vector<Joint>& joints() const { return data().joints; }
  const Joint& joint(int j) const { return data().joints[static_cast<std::size_t>(j)]; }
  const Joint& operator[](int j) const { return joint(j); }

  // Index of the joint with this exact name, or -1.
  int find(std::string_view name) const;
  bool is_root(int j) const { return joint(j).parent == kNoParent; }
  // Root joints, in index order.
  const std::vector<int>& roots() const { return data().roots; }
  // Children of j, in index order.
  std::span<const int> children(int j) const;
  // The root of the tree that holds j (constant time).
  int root_of(int j) const { return data().root[static_cast<std::size_t>(j)]; }
  // Number of edges from j up to its root (constant time).
  int depth(int j) const { return data().depth[static_cast<std::size_t>(j)]; }

  // Index of j's first channel within one frame's values; channels of joint j
  // occupy [channel_offset(j), channel_offset(j) + joint(j).channels.size()).
  int channel_offset(int j) const { return data().channel_offsets[static_cast<std::size_t>(j)]; }
  // Total number of channels per frame.
  int channel_count() const { return data().channel_count; }

  // True when both are copies of the same create() (so equal in everything):
  // a constant-time answer before comparing joints.
  bool shares(const Skeleton& other) const { return data_ && data_ == other.data_; }

 private:
  struct Data {
    std::vector<Joint> joints;
    std::vector<int> roots;
    std::vector<int> channel_offsets;
    std::vector<int> depth;        // per joint: edges up to its root
    std::vector<int> root;         // per joint: the root of its tree
    std::vector<int> child_begin;  // CSR: children of j are child_list[child_begin[j] .. child_begin[j+1])
    std::vector<int> child_list;
    int channel_count = 0;
  };
  // Immutable once made, so copies share it: a skeleton is copied with every
  // frame a live source publishes and every frame its views replay.
  std::shared_ptr<const Data> data_;
  const Data& data() const { return data_ ? *data_ : empty_data(); }
  static const Data& empty_data();
};

// Indices of the joints named `names`, in the same order; fails on the first
// unknown name ("unknown joint 'X'", ErrorKind::kNotFound).
Result<std::vector<int>> find_joints(const Skeleton& skeleton, std::span<const std::string> names);

}  // namespace gmr
