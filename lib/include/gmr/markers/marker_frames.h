// Marker frames solved one at a time (docs/markers.md, "Frame by frame"):
// what a live capture needs, where no frame after the current one exists.
//
// A calibration is solve_markers() run on a stretch of the take (the first
// seconds of a live source): each part's layout, each joint's place in its
// part and the bones it finds are kept. Each frame after is then solved
// alone: each part's weighted rigid fit to its layout with the outlier rule,
// the joints carried by their parts, the local transforms as solve_markers()
// builds them, the bones the calibration's. What a whole take does with the
// frames around a gap it cannot do: a part with fewer than 3 usable points
// holds its last fitted pose (counted); before its first fit the frame
// cannot be solved (refused, counted).
#pragma once

#include <cstddef>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/markers.h"
#include "gmr/motion/motion.h"

namespace gmr {

// What solving frames has met so far.
struct MarkerFrameCounts {
  std::size_t solved = 0;    // frames solved
  std::size_t refused = 0;   // frames refused: a part never fitted yet, or a coordinate not finite
  std::size_t held = 0;      // (frame, part) pairs that held the part's last pose
  std::size_t outliers = 0;  // (frame, marker) points left out by the outlier rule
  std::size_t missing = 0;   // (frame, marker) points the frame did not have
};

class MarkerFrameSolver {
 public:
  // Calibrates on frames [begin, end) of `markers` (end clamped to the take):
  // the errors solve_markers() gives for that stretch. Frames given to
  // solve() then hold the same markers in the same order (markers.names).
  static Result<MarkerFrameSolver> calibrate(const MarkerTrajectories& markers, const MarkerModel& model,
                                             std::size_t begin, std::size_t end);

  // The motion's skeleton: the model's joints, pre-rotation, the bones found
  // in the calibration, lengths in the marker units.
  const Skeleton& skeleton() const;
  // The markers a frame holds, in order (the calibration take's names).
  const std::vector<std::string>& marker_names() const;
  double millimetres_per_unit() const;

  // One frame: x, y, z per marker of marker_names() (NaN: missing) -> the
  // motion's channel values for it (skeleton().channel_count() of them).
  // Fails, counting it as refused, on a wrong size, an infinite coordinate, or
  // a part that was never fitted yet. Not thread-safe: it keeps the last poses.
  Result<std::vector<double>> solve(std::span<const double> positions);

  const MarkerFrameCounts& counts() const;

  MarkerFrameSolver(MarkerFrameSolver&&) noexcept;
  MarkerFrameSolver& operator=(MarkerFrameSolver&&) noexcept;
  ~MarkerFrameSolver();

  struct State;

 private:
  explicit MarkerFrameSolver(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

// Every frame of `markers` solved by a solver calibrated on its frames
// [begin, end): what a live source of the same take gives, frame for frame
// (`gmr convert --model M --calibrate-seconds S`). A frame that cannot be
// solved repeats the previous one (the first solved, before it).
Result<Motion> solve_marker_frames(const MarkerTrajectories& markers, const MarkerModel& model, std::size_t begin,
                                   std::size_t end, MarkerFrameCounts* counts = nullptr);

}  // namespace gmr
