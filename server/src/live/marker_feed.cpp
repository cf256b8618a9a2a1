#include "live/marker_feed.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>
#include <utility>

#include "gmr/core/names.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/marker_solve.h"
#include "streams/stream.h"

namespace gmr::server {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kFarthestMm = 1e7;      // a coordinate beyond 10 km is no marker
constexpr double kMaxCalibrationS = 10;  // the calibration's frames are held until it is made

}  // namespace

std::variant<MarkerFeed, Refusal> MarkerFeed::make(const pb::Publish& r, const ServerConfig& cfg) {
  const pb::MarkerStream& m = r.markers();
  auto bad = [](std::string why) { return Refusal{pb::ERROR_CODE_BAD_REQUEST, std::move(why)}; };
  if (r.name().empty()) return bad("a live source needs a name");
  if (const std::string why = name_problem(r.name()); !why.empty()) {
    return bad("source name " + printable(r.name(), 64) + ": " + why);
  }
  if (r.skeleton().joints_size() > 0) return bad("a marker publication sends markers, not a skeleton");
  if (m.names_size() == 0) return bad("a marker publication names its markers");
  if (static_cast<std::size_t>(m.names_size()) > cfg.max_live_joints) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED,
                   fmt::format("{} markers; a marker publication has at most {}", m.names_size(), cfg.max_live_joints)};
  }
  std::set<std::string> seen;
  for (int i = 0; i < m.names_size(); ++i) {
    const std::string& name = m.names(i);
    if (const std::string why = name_problem(name); !why.empty()) {
      return bad("marker " + std::to_string(i) + " name " + printable(name, 64) + ": " + why);
    }
    if (!seen.insert(name).second) return bad("marker name " + printable(name, 64) + " given twice");
  }
  const double ft = r.frame_time();
  if (!(std::isfinite(ft) && ft > 0.0 && 1.0 / ft >= kMinRateHz && 1.0 / ft <= kMaxRateHz)) {
    return bad(fmt::format("frame time {} s: the rate must be within [{}, {}] Hz", ft, kMinRateHz, kMaxRateHz));
  }
  auto model = builtin_marker_model(m.model());
  if (!model.ok()) {
    std::string known;
    for (const std::string& n : builtin_marker_model_names()) known += (known.empty() ? "" : ", ") + n;
    return bad("marker model " + printable(m.model(), 64) + " is not built in (built in: " + known + ")");
  }
  std::set<std::string, std::less<>> have;
  for (const std::string& name : m.names()) have.emplace(strip_subject_prefix(name));
  std::string lacking;
  std::size_t lacking_count = 0;
  for (const std::string& needed : model->marker_names()) {
    if (have.contains(needed)) continue;
    lacking += (lacking.empty() ? "" : ", ") + needed;
    ++lacking_count;
  }
  if (lacking_count > 0) {
    return Refusal{pb::ERROR_CODE_FAILED_PRECONDITION,
                   fmt::format("marker model {} needs {} marker{} the stream does not name: {}", m.model(),
                               lacking_count, lacking_count == 1 ? "" : "s", lacking)};
  }
  const double unit_mm = millimetres_per_marker_unit(m.units());
  if (!(unit_mm > 0)) return bad("marker units " + printable(m.units(), 16) + ": give mm, cm, m or in");
  const double seconds = m.calibration_seconds() == 0 ? 2.0 : m.calibration_seconds();
  if (!(seconds > 0 && seconds <= kMaxCalibrationS)) {
    return bad(fmt::format("calibration of {} s: give (0, {}] seconds", seconds, kMaxCalibrationS));
  }
  MarkerFeed feed;
  feed.model_ = std::move(model).value();
  feed.unit_mm_ = unit_mm;
  feed.calibration_.names.assign(m.names().begin(), m.names().end());
  feed.calibration_.frame_rate = 1.0 / ft;
  feed.calibration_.units = m.units().empty() ? "mm" : m.units();
  feed.calibration_frames_ = std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(seconds / ft - 1e-9)));
  return feed;
}

std::uint64_t MarkerFeed::held_bytes() const {
  return static_cast<std::uint64_t>(calibration_frames_) * calibration_.names.size() * 3 * sizeof(double);
}

Result<MarkerFeed::Taken> MarkerFeed::take(const pb::PublishFrame& frame) {
  const std::size_t n = calibration_.names.size();
  if (static_cast<std::size_t>(frame.values_size()) != 3 * n) {
    return make_error(ErrorKind::kInvalidArgument,
                      fmt::format("a marker frame of {} values; its {} markers need {} (x, y, z each)",
                                  frame.values_size(), n, 3 * n));
  }
  positions_.assign(frame.values().begin(), frame.values().end());
  missing_.assign(n, 0);
  for (const std::uint32_t k : frame.missing_markers()) {
    if (k >= n) return make_error(ErrorKind::kInvalidArgument, fmt::format("missing marker {} of {}", k, n));
    missing_[k] = 1;
    positions_[3 * k] = positions_[3 * k + 1] = positions_[3 * k + 2] = kNaN;
  }
  const double farthest = kFarthestMm / unit_mm_;
  for (std::size_t i = 0; i < 3 * n; ++i) {
    const double v = positions_[i];
    if (missing_[i / 3]) continue;
    if (!std::isfinite(v) || std::abs(v) > farthest) {
      return make_error(
          ErrorKind::kInvalidArgument,
          fmt::format("marker {} has coordinate {} = {}: {}", printable(calibration_.names[i / 3], 64), "xyz"[i % 3], v,
                      std::isnan(v) ? "not a number (a marker the frame lacks goes in missing_markers)"
                                    : "not finite or beyond 10 km"));
    }
  }
  ++frames_;
  if (calibration_out_) return Taken::kSkipped;  // the connection's reads wait while it computes
  if (!solver_) {
    calibration_.positions.insert(calibration_.positions.end(), positions_.begin(), positions_.end());
    return ++calibration_.frame_count < calibration_frames_ ? Taken::kCalibrating : Taken::kCalibrationDue;
  }
  auto values = solver_->solve(positions_);
  if (!values.ok()) {
    if (values.error().kind == ErrorKind::kFailedPrecondition) return Taken::kSkipped;
    return values.error();
  }
  values_ = std::move(values).value();
  return Taken::kSolved;
}

MarkerFeed::Calibration MarkerFeed::take_calibration() {
  calibration_out_ = true;
  MarkerTrajectories frames = calibration_;  // names, rate, units; the positions move
  frames.positions = std::exchange(calibration_.positions, {});
  calibration_.frame_count = 0;
  return Calibration{std::move(frames), model_};
}

Result<MarkerFrameSolver> MarkerFeed::Calibration::run() const {
  return MarkerFrameSolver::calibrate(frames, model, 0, frames.frame_count);
}

Status MarkerFeed::calibrated(Result<MarkerFrameSolver> solver) {
  calibration_out_ = false;
  if (!solver.ok()) {
    return make_error(ErrorKind::kFailedPrecondition, fmt::format("the calibration on the first {} frames failed: {}",
                                                                  calibration_frames_, solver.error().message));
  }
  solver_.emplace(std::move(solver).value());
  return Ok{};
}

}  // namespace gmr::server
