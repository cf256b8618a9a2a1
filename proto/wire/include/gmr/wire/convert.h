// lib types <-> protocol messages.
#pragma once

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"
#include "gmr/skeleton/skeleton.h"
#include "gmr/view/conventions.h"
#include "gmr/view/engine_pose.h"
#include "gmr/stream/v1/stream.pb.h"

namespace gmr::wire {

namespace pb = ::gmr::stream::v1;

void to_proto(const Skeleton& skeleton, pb::Skeleton& out);
// The motion's skeleton with its rest pose (engine_rest_pose) in the
// conventions of `basis`: what every skeleton the server sends carries.
void to_proto(const Motion& motion, const OutputBasis& basis, pb::Skeleton& out);
// Rebuilds and validates a skeleton from the wire (Skeleton::create's rules,
// plus: channel values in range).
Result<Skeleton> from_proto(const pb::Skeleton& message);
// The rest pose a skeleton message carries, one entry per joint (a joint
// without one, from an older server, gets the identity and its offset).
RestPose rest_from_proto(const pb::Skeleton& message);

// The protocol's code for a library error of `kind`: kNotFound -> NOT_FOUND,
// kFailedPrecondition -> FAILED_PRECONDITION, kResourceExhausted ->
// RESOURCE_EXHAUSTED, kInvalidArgument and kInvalidData -> BAD_REQUEST,
// kIo -> INTERNAL.
pb::ErrorCode error_code_for(ErrorKind kind);

// "NOT_FOUND" for ERROR_CODE_NOT_FOUND, etc.
const char* error_code_name(pb::ErrorCode code);

}  // namespace gmr::wire
