// Helpers of the fast-path tests: generated motions and position arrays.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <random>
#include <vector>

#include "gmr/fast/fast_fk.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "test_data.h"

namespace gmr::fast::test {

using namespace gmr::test;  // NOLINT: data_files, compare_positions, ...

// A random forest of 14 joints: two roots, rotation channels in random orders
// (0 to 3 of them), position channels on some non-roots, zero-length joints,
// angles up to +-400 degrees. all_roots: every joint a root with 3 position
// channels.
inline Motion random_motion(unsigned seed, Convention convention, std::size_t frames, bool all_roots = false) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> offset(-10.0, 10.0), angle(-400.0, 400.0), position(-50.0, 50.0);
  std::vector<Joint> joints;
  const int n = 14;
  for (int j = 0; j < n; ++j) {
    Joint joint;
    joint.name = "j";
    joint.name += std::to_string(j);  // (not "j" + ...: GCC 12 -Wrestrict false positive)
    const bool root = all_roots || j == 0 || j == 7;
    joint.parent = root ? kNoParent : static_cast<int>(rng() % static_cast<unsigned>(j));
    if (rng() % 5 != 0) joint.offset = Eigen::Vector3d(offset(rng), offset(rng), offset(rng));
    std::vector<ChannelType> rot = {ChannelType::kXrotation, ChannelType::kYrotation, ChannelType::kZrotation};
    std::shuffle(rot.begin(), rot.end(), rng);
    rot.resize(root ? 3 : rng() % 4);
    std::vector<ChannelType> pos;
    if (root) {
      pos = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
    } else if (rng() % 4 == 0) {
      pos = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
      std::shuffle(pos.begin(), pos.end(), rng);
      pos.resize(1 + rng() % 3);
    }
    if (rng() % 2) {
      joint.channels = pos;
      joint.channels.insert(joint.channels.end(), rot.begin(), rot.end());
    } else {
      joint.channels = rot;
      joint.channels.insert(joint.channels.end(), pos.begin(), pos.end());
    }
    joints.push_back(std::move(joint));
  }
  Motion m;
  m.skeleton = Skeleton::create(std::move(joints)).value();
  m.convention = convention;
  m.frame_time = 1.0 / 60.0;
  m.frame_count = frames;
  m.values.resize(frames * m.stride());
  for (std::size_t f = 0; f < frames; ++f) {
    for (int j = 0; j < n; ++j) {
      const Joint& joint = m.skeleton.joint(j);
      for (std::size_t i = 0; i < joint.channels.size(); ++i) {
        m.values[f * m.stride() + static_cast<std::size_t>(m.skeleton.channel_offset(j)) + i] =
            is_rotation(joint.channels[i]) ? angle(rng) : position(rng);
      }
    }
  }
  return m;
}

inline std::vector<Eigen::Vector3d> reference_positions(const Motion& m) { return compute_positions(m); }

// Positions of frames [b, e) from the fast range job, as frame-major doubles.
inline std::vector<Eigen::Vector3d> fast_positions(const CompiledMotion& cm, std::size_t b, std::size_t e,
                                                   Layout layout = Layout::kFrameMajor) {
  const std::size_t n = cm.joint_count();
  std::vector<float> ws(fk_workspace_size(cm)), pos((e - b) * n * 3);
  FkRangeJob job{.motion = &cm, .begin = b, .end = e, .layout = layout, .out_positions = pos, .workspace = ws};
  EXPECT_TRUE(job.run()) << job.check().error().to_string();
  std::vector<Eigen::Vector3d> out((e - b) * n);
  for (std::size_t f = 0; f < e - b; ++f) {
    for (std::size_t j = 0; j < n; ++j) {
      for (std::size_t a = 0; a < 3; ++a) {
        const std::size_t k = j * 3 + a;
        out[f * n + j][static_cast<int>(a)] = layout == Layout::kFrameMajor ? pos[f * n * 3 + k] : pos[k * (e - b) + f];
      }
    }
  }
  return out;
}

}  // namespace gmr::fast::test
