// The rig of a Retarget request (docs/retarget.md), checked as a live
// source's skeleton is: its size against --max-live-joints, a valid forest,
// and its reference pose against its channels.
#pragma once

#include <memory>
#include <variant>

#include "gmr/motion/motion.h"
#include "gmr/server/config.h"
#include "transport/net.h"

namespace gmr::server {

// The rig as a post-rotation motion with its reference pose as its one frame
// (none: it stands in its rest pose), or the refusal saying what is wrong.
std::variant<std::shared_ptr<const Motion>, Refusal> check_rig(const pb::Retarget& r, const ServerConfig& cfg);

}  // namespace gmr::server
