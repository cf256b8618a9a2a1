#include "gmr/core/limits.h"

namespace gmr {

Status check_frame_count(std::uint64_t frames, std::uint64_t bytes_per_frame, std::uint64_t bytes_available) {
  const std::string declared = "frame count " + std::to_string(frames);
  if (frames > kMaxFrames) {
    return make_error(ErrorKind::kInvalidData,
                      declared + " is above gmr's limit of " + std::to_string(kMaxFrames) + " frames per file");
  }
  if (bytes_per_frame == 0 && frames > kMaxEmptyFrames) {
    return make_error(ErrorKind::kInvalidData, declared + " is above gmr's limit of " +
                                                   std::to_string(kMaxEmptyFrames) +
                                                   " for frames that carry no data (no channels or markers)");
  }
  if (bytes_per_frame != 0 && bytes_available != UINT64_MAX && frames > bytes_available / bytes_per_frame) {
    return make_error(ErrorKind::kInvalidData, declared + " needs " + std::to_string(bytes_per_frame) +
                                                   " bytes per frame, but the file holds only " +
                                                   std::to_string(bytes_available) + " bytes for them");
  }
  return Ok{};
}

}  // namespace gmr
