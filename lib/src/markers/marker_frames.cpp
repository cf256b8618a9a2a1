// Marker frames solved one at a time on a calibration (gmr/markers/marker_frames.h).
#include "gmr/markers/marker_frames.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "part_fit.h"

namespace gmr {

using Eigen::Quaterniond;
using Eigen::Vector3d;
using marker_detail::fit_two_points;
using marker_detail::FramePart;
using marker_detail::PartFitter;
using marker_detail::Pose;
using marker_detail::solve_keeping;
using marker_detail::write_frame;

struct MarkerFrameSolver::State {
  MarkerModel model;
  std::vector<std::string> names;
  double unit_mm = 1;
  Skeleton skeleton;
  std::vector<FramePart> parts;
  std::vector<Vector3d> joint_local;
  MarkerFrameCounts counts;
  // Per frame, reused.
  std::vector<Pose> pose;
  std::vector<char> done;
  std::vector<Quaterniond> part_q;
  std::vector<Vector3d> joint_world, points, previous;
  PartFitter fitter;

  Vector3d marker(std::span<const double> positions, int index) const {
    const std::size_t i = static_cast<std::size_t>(index) * 3;
    return {positions[i], positions[i + 1], positions[i + 2]};
  }
  // Fits part `i` in this frame (its joint points already placed), or holds
  // its last pose; false when it has none.
  bool fit_part(std::size_t i, std::span<const double> positions) {
    if (done[i]) return true;
    FramePart& p = parts[i];
    const ModelPart& mp = model.parts[i];
    bool ok;
    if (mp.points.size() == 2) {
      const int j0 = p.joint_of[0];
      const std::size_t other = static_cast<std::size_t>(model.joints[static_cast<std::size_t>(j0)].part);
      if (!fit_part(other, positions)) return false;
      ok = fit_two_points(p.layout, pose[other], joint_world[static_cast<std::size_t>(j0)],
                          marker(positions, p.marker_of[1]), pose[i]);
    } else {
      points.resize(mp.points.size());
      for (std::size_t k = 0; k < points.size(); ++k) {
        points[k] = p.joint_of[k] >= 0 ? joint_world[static_cast<std::size_t>(p.joint_of[k])]
                                       : marker(positions, p.marker_of[k]);
      }
      double sum_sq = 0;
      std::size_t residuals = 0;
      ok = fitter.fit(p.layout, mp.weights, points, p.joint_of, model.outlier_mm / unit_mm, 2.0 / unit_mm, pose[i],
                      counts.outliers, sum_sq, residuals);
    }
    if (ok) {
      p.last = pose[i];
      p.fitted_once = true;
    } else {
      if (!p.fitted_once) return false;
      pose[i] = p.last;
      ++counts.held;
    }
    done[i] = 1;
    return true;
  }
};

MarkerFrameSolver::MarkerFrameSolver(std::unique_ptr<State> state) : state_(std::move(state)) {}
MarkerFrameSolver::MarkerFrameSolver(MarkerFrameSolver&&) noexcept = default;
MarkerFrameSolver& MarkerFrameSolver::operator=(MarkerFrameSolver&&) noexcept = default;
MarkerFrameSolver::~MarkerFrameSolver() = default;

Result<MarkerFrameSolver> MarkerFrameSolver::calibrate(const MarkerTrajectories& markers, const MarkerModel& model,
                                                       std::size_t begin, std::size_t end) {
  end = std::min(end, markers.frame_count);
  if (begin >= end) {
    return make_error(ErrorKind::kInvalidArgument, "calibrating markers: frames [" + std::to_string(begin) + ", " +
                                                       std::to_string(end) + ") hold no frame of the take's " +
                                                       std::to_string(markers.frame_count));
  }
  MarkerTrajectories stretch = markers;
  stretch.frame_count = end - begin;
  const std::size_t row = markers.names.size() * 3;
  stretch.positions.assign(markers.positions.begin() + static_cast<std::ptrdiff_t>(begin * row),
                           markers.positions.begin() + static_cast<std::ptrdiff_t>(end * row));
  stretch.residuals.clear();
  auto st = std::make_unique<State>();
  auto solved = solve_keeping(stretch, model, st->parts, st->joint_local);
  if (!solved) return solved.error();
  st->model = model;
  st->names = markers.names;
  st->unit_mm = solved->millimetres_per_unit;
  st->skeleton = solved->motion.skeleton;
  st->pose.assign(st->parts.size(), Pose{});
  st->done.assign(st->parts.size(), 0);
  st->part_q.assign(st->parts.size(), Quaterniond::Identity());
  st->joint_world.assign(model.joints.size(), Vector3d::Zero());
  st->previous.assign(model.joints.size(), Vector3d::Zero());
  return MarkerFrameSolver(std::move(st));
}

const Skeleton& MarkerFrameSolver::skeleton() const { return state_->skeleton; }
const std::vector<std::string>& MarkerFrameSolver::marker_names() const { return state_->names; }
double MarkerFrameSolver::millimetres_per_unit() const { return state_->unit_mm; }
const MarkerFrameCounts& MarkerFrameSolver::counts() const { return state_->counts; }

Result<std::vector<double>> MarkerFrameSolver::solve(std::span<const double> positions) {
  State& st = *state_;
  if (positions.size() != st.names.size() * 3) {
    ++st.counts.refused;
    return make_error(ErrorKind::kInvalidArgument,
                      "a marker frame holds " + std::to_string(positions.size()) + " coordinates; the calibration's " +
                          std::to_string(st.names.size()) + " markers need " + std::to_string(st.names.size() * 3));
  }
  std::size_t missing = 0;
  for (std::size_t i = 0; i < positions.size(); i += 3) {
    const double x = positions[i], y = positions[i + 1], z = positions[i + 2];
    if (std::isnan(x) || std::isnan(y) || std::isnan(z)) {
      ++missing;
    } else if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
      ++st.counts.refused;
      return make_error(ErrorKind::kInvalidArgument, "marker '" + st.names[i / 3] + "' has an infinite coordinate");
    }
  }
  std::fill(st.done.begin(), st.done.end(), 0);
  for (std::size_t j = 0; j < st.model.joints.size(); ++j) {
    const std::size_t part = static_cast<std::size_t>(st.model.joints[j].part);
    if (!st.fit_part(part, positions)) {
      ++st.counts.refused;
      return make_error(ErrorKind::kFailedPrecondition, "part '" + st.model.parts[part].name +
                                                            "' has not been fitted in any frame yet (fewer than 3 "
                                                            "usable points so far)");
    }
    st.joint_world[j] = st.pose[part].apply(st.joint_local[j]);
  }
  for (std::size_t i = 0; i < st.parts.size(); ++i) st.part_q[i] = st.pose[i].q;
  std::vector<double> values(static_cast<std::size_t>(st.skeleton.channel_count()));
  write_frame(st.skeleton, st.model, st.part_q, st.joint_world, st.previous, st.counts.solved == 0, values);
  st.counts.missing += missing;
  ++st.counts.solved;
  return values;
}

Result<Motion> solve_marker_frames(const MarkerTrajectories& markers, const MarkerModel& model, std::size_t begin,
                                   std::size_t end, MarkerFrameCounts* counts) {
  auto solver = MarkerFrameSolver::calibrate(markers, model, begin, end);
  if (!solver) return solver.error();
  Motion motion;
  motion.skeleton = solver->skeleton();
  motion.convention = Convention::kPreRotation;
  motion.frame_time = markers.frame_rate > 0 ? 1.0 / markers.frame_rate : 0.0;
  motion.frame_count = markers.frame_count;
  const std::size_t stride = motion.stride();
  motion.values.assign(markers.frame_count * stride, 0.0);
  const std::size_t row = markers.names.size() * 3;
  std::size_t first_solved = markers.frame_count;
  for (std::size_t f = 0; f < markers.frame_count; ++f) {
    auto values = solver->solve(std::span<const double>(markers.positions).subspan(f * row, row));
    if (values) {
      std::copy(values->begin(), values->end(), motion.frame(f).begin());
      if (first_solved == markers.frame_count) first_solved = f;
    } else if (f > 0 && first_solved < f) {
      std::copy(motion.frame(f - 1).begin(), motion.frame(f - 1).end(), motion.frame(f).begin());
    }
  }
  if (first_solved == markers.frame_count) {
    return make_error(ErrorKind::kInvalidData, "no frame of the take could be solved");
  }
  for (std::size_t f = 0; f < first_solved; ++f) {
    std::copy(motion.frame(first_solved).begin(), motion.frame(first_solved).end(), motion.frame(f).begin());
  }
  if (counts) *counts = solver->counts();
  if (auto s = motion.validate(); !s) return s.error();
  return motion;
}

}  // namespace gmr
