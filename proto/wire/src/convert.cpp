#include "gmr/wire/convert.h"

#include <string>

namespace gmr::wire {

void to_proto(const Skeleton& skeleton, pb::Skeleton& out) {
  out.Clear();
  out.mutable_joints()->Reserve(static_cast<int>(skeleton.size()));
  for (const Joint& j : skeleton.joints()) {
    pb::Joint* m = out.add_joints();
    m->set_name(j.name);
    m->set_parent(j.parent);
    m->set_soft_parent(j.soft_parent);
    m->mutable_offset()->set_x(j.offset.x());
    m->mutable_offset()->set_y(j.offset.y());
    m->mutable_offset()->set_z(j.offset.z());
    for (ChannelType c : j.channels) m->add_channels(static_cast<pb::ChannelType>(static_cast<int>(c)));
  }
}

void to_proto(const Motion& motion, const OutputBasis& basis, pb::Skeleton& out) {
  to_proto(motion.skeleton, out);
  out.set_metres_per_unit(basis.metres_per_unit);
  const RestPose rest = engine_rest_pose(motion, basis);
  for (int i = 0; i < out.joints_size(); ++i) {
    const auto u = static_cast<std::size_t>(i);
    pb::Joint* m = out.mutable_joints(i);
    m->mutable_rest_translation()->set_x(rest.translations[u].x());
    m->mutable_rest_translation()->set_y(rest.translations[u].y());
    m->mutable_rest_translation()->set_z(rest.translations[u].z());
    m->mutable_rest_rotation()->set_x(rest.rotations[u].x());
    m->mutable_rest_rotation()->set_y(rest.rotations[u].y());
    m->mutable_rest_rotation()->set_z(rest.rotations[u].z());
    m->mutable_rest_rotation()->set_w(rest.rotations[u].w());
  }
}

RestPose rest_from_proto(const pb::Skeleton& message) {
  RestPose rest;
  for (const pb::Joint& m : message.joints()) {
    if (m.has_rest_rotation()) {
      const auto& q = m.rest_rotation();
      rest.rotations.emplace_back(q.w(), q.x(), q.y(), q.z());
    } else {
      rest.rotations.push_back(Eigen::Quaterniond::Identity());
    }
    const auto& t = m.has_rest_translation() ? m.rest_translation() : m.offset();
    rest.translations.emplace_back(t.x(), t.y(), t.z());
  }
  return rest;
}

Result<Skeleton> from_proto(const pb::Skeleton& message) {
  std::vector<Joint> joints;
  joints.reserve(static_cast<std::size_t>(message.joints_size()));
  for (int i = 0; i < message.joints_size(); ++i) {
    const pb::Joint& m = message.joints(i);
    Joint j;
    j.name = m.name();
    j.parent = m.parent();
    j.soft_parent = m.soft_parent();
    j.offset = Eigen::Vector3d(m.offset().x(), m.offset().y(), m.offset().z());
    for (int c : m.channels()) {
      if (c < 0 || c > 5)
        return make_error("joint " + std::to_string(i) + ": unknown channel type " + std::to_string(c));
      j.channels.push_back(static_cast<ChannelType>(c));
    }
    joints.push_back(std::move(j));
  }
  return Skeleton::create(std::move(joints));
}

pb::ErrorCode error_code_for(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::kNotFound:
      return pb::ERROR_CODE_NOT_FOUND;
    case ErrorKind::kFailedPrecondition:
      return pb::ERROR_CODE_FAILED_PRECONDITION;
    case ErrorKind::kResourceExhausted:
      return pb::ERROR_CODE_RESOURCE_EXHAUSTED;
    case ErrorKind::kInvalidArgument:
    case ErrorKind::kInvalidData:
      return pb::ERROR_CODE_BAD_REQUEST;
    case ErrorKind::kIo:
      return pb::ERROR_CODE_INTERNAL;
  }
  return pb::ERROR_CODE_INTERNAL;
}

const char* error_code_name(pb::ErrorCode code) {
  switch (code) {
    case pb::ERROR_CODE_BAD_REQUEST:
      return "BAD_REQUEST";
    case pb::ERROR_CODE_UNKNOWN_REQUEST:
      return "UNKNOWN_REQUEST";
    case pb::ERROR_CODE_VERSION_MISMATCH:
      return "VERSION_MISMATCH";
    case pb::ERROR_CODE_NOT_FOUND:
      return "NOT_FOUND";
    case pb::ERROR_CODE_FAILED_PRECONDITION:
      return "FAILED_PRECONDITION";
    case pb::ERROR_CODE_RESOURCE_EXHAUSTED:
      return "RESOURCE_EXHAUSTED";
    case pb::ERROR_CODE_HANDSHAKE_REQUIRED:
      return "HANDSHAKE_REQUIRED";
    case pb::ERROR_CODE_INTERNAL:
      return "INTERNAL";
    case pb::ERROR_CODE_UNAUTHENTICATED:
      return "UNAUTHENTICATED";
    case pb::ERROR_CODE_PERMISSION_DENIED:
      return "PERMISSION_DENIED";
    default:
      return "UNSPECIFIED";
  }
}

}  // namespace gmr::wire
