// From raw markers to a GMR motion (the paper's section 5.1).
//
// Given marker trajectories and a skeleton model (gmr/markers/marker_model.h):
// 1. Each part's layout (its markers, and the joints it carries, in one rigid
//    frame) is calibrated over the take: a Procrustes mean of the frames that
//    see all of its points. A part of 2 points (a joint of another part, then
//    a marker) takes its twist from that other part.
// 2. Each frame, each part's frame is the weighted least-squares rigid fit
//    (Kabsch) of its layout to its visible points; a point farther than the
//    model's outlier distance from the fit is left out and the fit redone
//    while 3 points remain. A frame with fewer than 3 usable points is
//    interpolated between the nearest fitted frames (slerp), or held at the
//    ends of the take, and counted.
// 3. Joints are placed in model order. `at EXPR`: the median of EXPR in its
//    part's frame over the take, then carried by the part. `centre CHILD`: the
//    point fixed in its part about which CHILD's markers keep constant
//    distances (a least-squares sphere fit with one centre and a radius per
//    marker, in the part's frame, over all fitted frames); along directions
//    the take barely moves the markers (the model's min-spread rules) the
//    prior decides instead, so a joint that does not move is at its prior;
//    a `hinge` takes only its best-determined direction from the take.
// 4. The motion: every joint's world frame is its part's frame at the joint,
//    M_c; L_c = M_p(c)^-1 M_c in the pre-rotation convention, the offset t_c
//    the mean of R_c^T (p_c - p_p(c)) over the take; roots carry the joint's
//    world position. No dummy joints: a joint that shares its parent's part
//    has no rotation channels.
// Lengths come out in the marker file's units.
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/markers.h"
#include "gmr/motion/motion.h"

namespace gmr {

struct MarkerSolveOptions {
  // Essential joints: the roots of the result (model joint names). Empty:
  // the model's own roots (the first joint: the pelvis in cmu41).
  std::vector<std::string> roots;
};

struct PartFit {
  std::string name;
  std::size_t fitted = 0;        // frames fitted from 3 or more points (2 for a 2-point part)
  std::size_t interpolated = 0;  // frames between fitted ones
  std::size_t held = 0;          // frames before the first or after the last fitted one
  std::size_t outliers = 0;      // (frame, marker) points left out as outliers
  // RMS distance of the visible points to the fitted frame over fitted frames
  // (file units).
  double fit_rms = 0;
  // RMS distance between the measured markers and the markers carried
  // rigidly by the reconstructed motion, over the frames they are visible
  // (file units); NaN when no joint carries the part.
  double motion_rms = 0;
  double motion_max = 0;
};

struct JointFit {
  std::string name;
  bool functional = false;    // found by a centre fit (else placed by its `at` expression)
  int determined = 0;         // centre: directions (0..3) the take determined; the rest from the prior
  double prior_distance = 0;  // centre: distance from the prior (file units)
  double fit_rms = 0;         // centre: RMS of the marker-distance residuals (file units)
  double split_shift = 0;     // split: how far the chain's proportion moved it (file units)
  // RMS variation of the bone parent -> joint over the take (file units),
  // made constant in the motion.
  double bone_rms = 0;
  double bone_length = 0;
};

// A marker carried by a joint of the motion: world = P_joint + W_joint * offset.
struct CarriedMarker {
  std::string marker;     // as named in the model
  int marker_index = -1;  // in the marker file
  int joint = -1;         // in the motion's skeleton
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();
  int part = -1;  // in the model
};

struct MarkerSolveResult {
  Motion motion;                 // pre-rotation
  std::vector<PartFit> parts;    // model order
  std::vector<JointFit> joints;  // model order
  std::vector<CarriedMarker> carried;
  double millimetres_per_unit = 1;  // of the marker file (and the motion)
  Warnings warnings;
};

// Builds the motion. `model` comes from parse_marker_model() (or
// read_marker_model(), builtin_marker_model()): the solver relies on the
// parser's checks (references resolved, every parent and part defined before
// its use) and does not repeat them. Errors: a marker the model needs missing from the file
// (all of them named), a file without frames or frame rate units that are not
// a length, a part whose points are never all seen together, a root that is
// not a model joint.
Result<MarkerSolveResult> solve_markers(const MarkerTrajectories& markers, const MarkerModel& model,
                                        const MarkerSolveOptions& options = {});

// The carried markers' world positions in frame f of `motion` (one per
// CarriedMarker).
std::vector<Eigen::Vector3d> carried_marker_positions(const Motion& motion, const std::vector<CarriedMarker>& carried,
                                                      std::size_t f);

// Millimetres per unit for a marker file's units ("mm", "cm", "m", "in"; case-
// insensitive); 0 when not a length unit. Empty units count as millimetres.
double millimetres_per_marker_unit(std::string_view units);

}  // namespace gmr
