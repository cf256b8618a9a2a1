// What a live view's edits are, spelled out (ViewContent::live_key): views of
// one live source whose keys are equal make equal frames from each frame the
// source publishes, so the source replays their edits once for all of them.
// Each field is length-prefixed: two different edit lists never spell the
// same text, and ViewEdit keeps its SHA-256 (transport/digest.h).
#pragma once

#include <string>
#include <string_view>

#include "gmr/motion/motion.h"

namespace gmr::server {

class LiveKey {
 public:
  explicit LiveKey(std::string_view edit) { put(edit); }

  LiveKey& put(std::string_view field);
  LiveKey& put_number(double x);
  // The skeleton (names, parents, soft parents, offsets, channels), the
  // convention, and the frames when `with_values`.
  LiveKey& put_motion(const Motion& m, bool with_values);

  std::string take() { return std::move(key_); }  // leaves the key empty

 private:
  std::string key_;
};

}  // namespace gmr::server
