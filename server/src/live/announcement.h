// What a live source's announcement (a Publish) must be, checked the same way
// whether a client publishes it or another replica relays it.
#pragma once

#include <variant>

#include "gmr/motion/motion.h"
#include "gmr/server/config.h"
#include "transport/net.h"

namespace gmr::server {

// The name, the skeleton (its size against cfg.max_live_joints), the frame
// rate (within the streams' rates) and the unit of `r`: the skeleton, or the
// refusal saying what is wrong.
std::variant<Skeleton, Refusal> check_announcement(const pb::Publish& r, const ServerConfig& cfg);

}  // namespace gmr::server
