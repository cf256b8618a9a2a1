// A stream's frame, computed and encoded once for all its targets: forward
// kinematics (the float path through the server's FkBlocks for float32
// streams whose motion compiled, else the double reference path), the
// viewpoint and conventions, local transforms when asked for, and the shared
// Frame body (wire::encode_frame_body).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "gmr/server/view.h"
#include "streams/stream.h"

namespace gmr::server {

// Frame `frame` of `content`'s motion as the Frame body clients are told is
// frame `index`, number `sequence` of its stream; `own_frames`: the motion's
// own_frame_sources when `settings` asks for local transforms. Counts what it
// computed in `counters`.
std::shared_ptr<const std::string> encode_frame(const ViewContent& content, const Stream::Settings& settings,
                                                std::span<const int> own_frames, std::uint64_t frame,
                                                std::uint64_t index, std::uint64_t sequence, StreamCounters& counters);

}  // namespace gmr::server
