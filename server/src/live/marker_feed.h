// A live source of labelled markers (docs/protocol.md, "Live markers"): the
// publisher names its markers and a built-in skeleton model once, then sends
// x, y, z per marker each frame, saying which it lacks. The first seconds of
// frames calibrate the model (gmr/markers/marker_frames.h), computed off the
// control loop (a Calibration, run on the edit pool); from then on each frame
// is solved alone into the model's skeleton, which the publication serves as
// an ordinary live source.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "gmr/markers/marker_frames.h"
#include "gmr/markers/markers.h"
#include "gmr/server/config.h"
#include "transport/net.h"

namespace gmr::server {

class MarkerFeed {
 public:
  // The markers of `r` (names, model, units, calibration), checked: every
  // marker the model needs among the names (the refusal lists those it
  // lacks), names unique and printable, the rate within the streams'.
  static std::variant<MarkerFeed, Refusal> make(const pb::Publish& r, const ServerConfig& cfg);

  enum class Taken {
    kCalibrating,     // kept for the calibration
    kCalibrationDue,  // the last calibration frame: take_calibration(), run it, give it to calibrated()
    kSolved,          // values() holds the frame's channel values
    kSkipped,         // not solved: a part not fitted yet (counted), or the calibration not back yet
  };
  // One frame: refused (the error says where and what) when its size or
  // missing list is wrong, or a coordinate it has is not finite or absurd
  // (beyond 10 km).
  Result<Taken> take(const pb::PublishFrame& frame);

  // The calibration's frames and model, moved out to be computed anywhere
  // (about 20 ms for 2 s of 41 markers in Release; seconds under a sanitizer).
  struct Calibration {
    MarkerTrajectories frames;
    MarkerModel model;
    Result<MarkerFrameSolver> run() const;
  };
  // Once take() said kCalibrationDue; the feed then holds no frames.
  Calibration take_calibration();
  // The calibration's outcome: the solver from now on, or why there is none
  // (the error says on how many frames it failed).
  Status calibrated(Result<MarkerFrameSolver> solver);

  const Skeleton& skeleton() const { return solver_->skeleton(); }
  double metres_per_unit() const { return unit_mm_ / 1000.0; }
  const std::vector<double>& values() const { return values_; }
  // Frames taken so far (calibration ones included): the take's frame index.
  std::uint64_t frames() const { return frames_; }
  // Bytes it holds: the calibration frames (in the memory budget; the
  // publication counts them until the skeleton replaces them).
  std::uint64_t held_bytes() const;
  const MarkerFrameCounts* counts() const { return solver_ ? &solver_->counts() : nullptr; }
  std::size_t calibration_frames() const { return calibration_frames_; }

 private:
  MarkerFeed() = default;

  MarkerModel model_;
  MarkerTrajectories calibration_;  // the frames so far, until calibrated
  std::size_t calibration_frames_ = 0;
  bool calibration_out_ = false;  // taken, not back yet
  double unit_mm_ = 1;
  std::optional<MarkerFrameSolver> solver_;
  std::vector<double> positions_, values_;
  std::vector<char> missing_;  // per marker, this frame
  std::uint64_t frames_ = 0;
};

}  // namespace gmr::server
