// lib types <-> protocol messages.
#pragma once

#include "gmr/core/error.h"
#include "gmr/skeleton/skeleton.h"
#include "gmr/stream/v1/stream.pb.h"

namespace gmr::wire {

namespace pb = ::gmr::stream::v1;

void to_proto(const Skeleton& skeleton, pb::Skeleton& out);
// Rebuilds and validates a skeleton from the wire (Skeleton::create's rules,
// plus: channel values in range).
Result<Skeleton> from_proto(const pb::Skeleton& message);

// The protocol's code for a library error of `kind`: kNotFound -> NOT_FOUND,
// kFailedPrecondition -> FAILED_PRECONDITION, kResourceExhausted ->
// RESOURCE_EXHAUSTED, kInvalidArgument and kInvalidData -> BAD_REQUEST,
// kIo -> INTERNAL.
pb::ErrorCode error_code_for(ErrorKind kind);

// "NOT_FOUND" for ERROR_CODE_NOT_FOUND, etc.
const char* error_code_name(pb::ErrorCode code);

}  // namespace gmr::wire
