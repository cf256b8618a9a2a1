#include "gmr/motion/motion.h"

#include <cmath>

namespace gmr {

Eigen::Matrix3d Motion::local_rotation(std::size_t f, int j) const {
  return compose_rotation(skeleton.joint(j).channels, joint_values(f, j));
}

Eigen::Vector3d Motion::local_offset(std::size_t f, int j) const {
  const Joint& joint = skeleton.joint(j);
  Eigen::Vector3d t = joint.offset;
  const auto v = joint_values(f, j);
  for (std::size_t i = 0; i < joint.channels.size(); ++i) {
    if (is_position(joint.channels[i])) t[static_cast<int>(axis_of(joint.channels[i]))] = v[i];
  }
  return t;
}

Status Motion::validate() const {
  if (!std::isfinite(frame_time) || frame_time < 0.0) return make_error("frame time must be finite and >= 0");
  if (values.size() != frame_count * stride()) {
    return make_error("motion has " + std::to_string(values.size()) + " values, expected " +
                      std::to_string(frame_count) + " frames x " + std::to_string(stride()) + " channels");
  }
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (!std::isfinite(values[i])) {
      return make_error("value " + std::to_string(i % stride()) + " of frame " + std::to_string(i / stride()) +
                        " is not finite");
    }
  }
  return Ok{};
}

}  // namespace gmr
