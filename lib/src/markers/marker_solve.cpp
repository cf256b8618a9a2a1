// From raw markers to a GMR motion: part fits, joint centres, local transforms.
#include "gmr/markers/marker_solve.h"

#include "part_fit.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/set_roots.h"

namespace gmr {
namespace {

using Eigen::Matrix3d;
using Eigen::Quaterniond;
using Eigen::Vector3d;
using marker_detail::fit_two_points;
using marker_detail::FramePart;
using marker_detail::PartFitter;
using marker_detail::Pose;
using marker_detail::write_frame;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

bool finite(const Vector3d& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

enum class State : unsigned char { kNone, kFitted, kInterpolated, kHeld };

// Weighted least-squares rigid fit (Kabsch): the pose that takes `local` onto
// `world`. False when the points are (nearly) collinear: their spread across
// the best line is below `min_spread`.
bool fit_rigid(const std::vector<Vector3d>& local, const std::vector<Vector3d>& world, const std::vector<double>& w,
               double min_spread, Pose& out) {
  double total = 0;
  Vector3d cl = Vector3d::Zero(), cw = Vector3d::Zero();
  for (std::size_t i = 0; i < local.size(); ++i) {
    total += w[i];
    cl += w[i] * local[i];
    cw += w[i] * world[i];
  }
  if (!(total > 0)) return false;
  cl /= total;
  cw /= total;
  Matrix3d h = Matrix3d::Zero();
  for (std::size_t i = 0; i < local.size(); ++i) h += w[i] * (local[i] - cl) * (world[i] - cw).transpose();
  Eigen::JacobiSVD<Matrix3d> svd(h, Eigen::ComputeFullU | Eigen::ComputeFullV);
  if (!(svd.singularValues()(1) / total >= min_spread * min_spread)) return false;
  const Matrix3d& u = svd.matrixU();
  const Matrix3d& v = svd.matrixV();
  Matrix3d d = Matrix3d::Identity();
  d(2, 2) = (v * u.transpose()).determinant() < 0 ? -1 : 1;
  const Matrix3d r = v * d * u.transpose();
  out.q = Quaterniond(r).normalized();
  out.t = cw - r * cl;
  return true;
}

double median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

// The median of each coordinate of a point in a part's frame, over the
// frames where `world(f)` (the point in the world) is finite; nullopt when
// it never is.
template <class World>
std::optional<Vector3d> median_in_part(const std::vector<marker_detail::Pose>& poses, std::size_t frames, World world) {
  std::vector<double> xs, ys, zs;
  for (std::size_t f = 0; f < frames; ++f) {
    const Vector3d w = world(f);
    if (!finite(w)) continue;
    const Vector3d l = poses[f].local(w);
    xs.push_back(l.x());
    ys.push_back(l.y());
    zs.push_back(l.z());
  }
  if (xs.empty()) return std::nullopt;
  return Vector3d(median(xs), median(ys), median(zs));
}

class Solver {
 public:
  Solver(const MarkerTrajectories& m, const MarkerModel& model) : m_(m), model_(model) {}
  Result<MarkerSolveResult> run(const MarkerSolveOptions& options);
  // After run(): each part's layout and points, each joint's place in its part.
  void keep(std::vector<FramePart>& parts, std::vector<Vector3d>& joint_local) const {
    parts.assign(parts_.size(), FramePart{});
    for (std::size_t i = 0; i < parts_.size(); ++i) {
      parts[i].layout = parts_[i].layout;
      parts[i].marker_of = parts_[i].marker_of;
      parts[i].joint_of = parts_[i].joint_of;
    }
    joint_local = joint_local_;
  }

 private:
  struct Part {
    bool solved = false;
    std::vector<Vector3d> layout;  // per point, in the part's frame
    std::vector<Pose> poses;       // per frame
    std::vector<State> state;      // per frame
    std::vector<int> marker_of;    // per point: marker index in the file, or -1 for a joint
    std::vector<int> joint_of;     // per point: joint index, or -1 for a marker
  };

  Error error(std::string message, int line = 0) const {
    Error e;
    e.file = model_.name.empty() ? std::string("<marker model>") : "marker model " + model_.name;
    e.line = line;
    e.message = std::move(message);
    return e;
  }
  Vector3d marker(int index, std::size_t f) const {
    const std::size_t i = m_.index(f, static_cast<std::size_t>(index));
    return {m_.positions[i], m_.positions[i + 1], m_.positions[i + 2]};
  }
  Vector3d point(const Part& p, std::size_t k, std::size_t f) const {
    if (p.joint_of[k] >= 0) return joint_world_[static_cast<std::size_t>(p.joint_of[k])][f];
    return marker(p.marker_of[k], f);
  }
  Vector3d eval(const PointExpr& e, std::size_t f) const;
  Status resolve_markers();
  Status solve_part(int index);
  Status calibrate(int index);
  void fill(Part& p, std::size_t& interpolated, std::size_t& held) const;
  Status place_joint(int index);
  void reset();
  Status place_all();
  bool split_chains(bool first_round, bool apply);
  Status place_again(std::size_t first_warning);
  Result<Motion> build_motion();
  void report_motion(MarkerSolveResult& r) const;

  const MarkerTrajectories& m_;
  const MarkerModel& model_;
  double unit_mm_ = 1;  // millimetres per file unit
  std::map<std::string, int, std::less<>> marker_index_;
  std::vector<Part> parts_;
  std::vector<PartFit> part_fits_;
  std::vector<JointFit> joint_fits_;
  std::vector<std::vector<Vector3d>> joint_world_;  // per joint, per frame
  std::vector<Vector3d> joint_local_;               // per joint, in its part
  // Splits, per joint: where place_joint found it before its split, where the
  // split puts it, the last round's offset along the bone and how far that
  // was from the split's target (for the secant step).
  struct SplitRound {
    bool seen = false;
    double offset = 0, gap = 0;
  };
  std::vector<Vector3d> found_local_;
  std::vector<std::optional<Vector3d>> split_local_;
  std::vector<SplitRound> split_rounds_;
  Warnings warnings_;
  Warnings split_warnings_;  // after the others: rounds of placing again do not repeat them
};

Vector3d Solver::eval(const PointExpr& e, std::size_t f) const {
  switch (e.kind) {
    case PointExpr::Kind::kMarker:
      return marker(marker_index_.find(e.name)->second, f);
    case PointExpr::Kind::kJoint:
      return joint_world_[static_cast<std::size_t>(model_.find_joint(e.name))][f];
    case PointExpr::Kind::kMean: {
      Vector3d s = Vector3d::Zero();
      for (const PointExpr& a : e.args) s += eval(a, f);
      return s / static_cast<double>(e.args.size());
    }
    case PointExpr::Kind::kAlong: {
      const Vector3d a = eval(e.args[0], f), b = eval(e.args[1], f), c = eval(e.args[2], f);
      const Vector3d d = c - b;
      const double n = d.norm();
      if (!(n > 0)) return Vector3d::Constant(kNaN);
      const double len = e.absolute[0] ? e.lengths[0] / unit_mm_ : e.lengths[0] * n;
      return a + len * d / n;
    }
    case PointExpr::Kind::kLocal: {
      const Vector3d o = eval(e.args[0], f), xp = eval(e.args[1], f), pp = eval(e.args[2], f);
      const double unit = (xp - o).norm();
      if (!(unit > 0)) return Vector3d::Constant(kNaN);
      const Vector3d x = (xp - o) / unit;
      Vector3d z = x.cross(pp - o);
      if (!(z.norm() > 0)) return Vector3d::Constant(kNaN);
      z.normalize();
      const Vector3d y = z.cross(x);
      auto len = [&](int k) { return e.absolute[k] ? e.lengths[k] / unit_mm_ : e.lengths[k] * unit; };
      return o + len(0) * x + len(1) * y + len(2) * z;
    }
  }
  return Vector3d::Constant(kNaN);
}

Status Solver::resolve_markers() {
  // Names after the subject prefix; the first of a repeated name wins.
  std::map<std::string, int, std::less<>> by_name;
  for (std::size_t i = 0; i < m_.names.size(); ++i) {
    by_name.emplace(std::string(strip_subject_prefix(m_.names[i])), static_cast<int>(i));
  }
  std::string missing;
  std::size_t missing_count = 0;
  for (const std::string& n : model_.marker_names()) {
    auto it = by_name.find(n);
    if (it == by_name.end()) {
      missing += (missing.empty() ? "" : ", ") + n;
      ++missing_count;
      continue;
    }
    marker_index_.emplace(n, it->second);
  }
  if (missing_count > 0) {
    return error("the marker file lacks " + std::to_string(missing_count) + " marker" +
                 (missing_count == 1 ? "" : "s") + " the model needs: " + missing);
  }
  return Ok{};
}

// The layout: with 3+ points, a Procrustes mean over the frames that see them
// all; with 2 (a joint of another part, a marker), the marker's mean
// direction and distance from the joint in that other part's frame.
Status Solver::calibrate(int index) {
  const ModelPart& mp = model_.parts[static_cast<std::size_t>(index)];
  Part& p = parts_[static_cast<std::size_t>(index)];
  const std::size_t n = mp.points.size();
  if (n == 2) {
    const int j0 = p.joint_of[0];
    const Part& q = parts_[static_cast<std::size_t>(model_.joints[static_cast<std::size_t>(j0)].part)];
    Vector3d dir = Vector3d::Zero();
    double length = 0;
    std::size_t count = 0;
    for (std::size_t f = 0; f < m_.frame_count; ++f) {
      const Vector3d d = point(p, 1, f) - point(p, 0, f);
      if (!finite(d) || !(d.norm() > 0)) continue;
      dir += q.poses[f].q.conjugate() * d.normalized();
      length += d.norm();
      ++count;
    }
    if (count == 0 || !(dir.norm() > 0)) {
      return error("part '" + mp.name + "': marker '" + mp.points[1] + "' is never visible", mp.line);
    }
    p.layout = {Vector3d::Zero(), dir.normalized() * (length / static_cast<double>(count))};
    return Ok{};
  }
  std::vector<std::size_t> complete;
  for (std::size_t f = 0; f < m_.frame_count; ++f) {
    bool all = true;
    for (std::size_t k = 0; k < n && all; ++k) all = finite(point(p, k, f));
    if (all) complete.push_back(f);
  }
  if (complete.empty()) {
    return error("part '" + mp.name +
                     "': its points are never all visible in one frame, so its layout cannot be "
                     "calibrated",
                 mp.line);
  }
  // At most 1,000 frames, evenly spread, make the mean.
  if (complete.size() > 1000) {
    std::vector<std::size_t> some;
    for (std::size_t i = 0; i < 1000; ++i) some.push_back(complete[i * complete.size() / 1000]);
    complete.swap(some);
  }
  std::vector<Vector3d> layout(n), world(n);
  for (std::size_t k = 0; k < n; ++k) layout[k] = point(p, k, complete[0]);
  Vector3d c = Vector3d::Zero();
  for (const Vector3d& v : layout) c += v;
  c /= static_cast<double>(n);
  for (Vector3d& v : layout) v -= c;
  // From the second pass on, a frame with a point beyond the outlier
  // distance (a swapped or ghost marker) stays out of the mean.
  const double outlier = model_.outlier_mm / unit_mm_;
  for (int iteration = 0; iteration < 4; ++iteration) {
    std::vector<Vector3d> sum(n, Vector3d::Zero());
    std::size_t used = 0;
    for (std::size_t f : complete) {
      for (std::size_t k = 0; k < n; ++k) world[k] = point(p, k, f);
      Pose pose;
      if (!fit_rigid(layout, world, mp.weights, 0.0, pose)) continue;
      bool inlier = true;
      for (std::size_t k = 0; k < n && inlier && iteration > 0; ++k) {
        inlier = (pose.apply(layout[k]) - world[k]).norm() <= outlier;
      }
      if (!inlier) continue;
      for (std::size_t k = 0; k < n; ++k) sum[k] += pose.local(world[k]);
      ++used;
    }
    if (used == 0) break;
    c.setZero();
    for (std::size_t k = 0; k < n; ++k) {
      layout[k] = sum[k] / static_cast<double>(used);
      c += layout[k];
    }
    c /= static_cast<double>(n);
    for (Vector3d& v : layout) v -= c;
  }
  p.layout = std::move(layout);
  return Ok{};
}

void Solver::fill(Part& p, std::size_t& interpolated, std::size_t& held) const {
  const std::size_t frames = m_.frame_count;
  std::size_t prev = frames;  // last fitted frame seen, frames = none
  for (std::size_t f = 0; f < frames; ++f) {
    if (p.state[f] == State::kFitted) {
      prev = f;
      continue;
    }
    std::size_t next = f + 1;
    while (next < frames && p.state[next] != State::kFitted) ++next;
    for (std::size_t g = f; g < next; ++g) {
      if (prev < frames && next < frames) {
        const double a = static_cast<double>(g - prev) / static_cast<double>(next - prev);
        p.poses[g].q = p.poses[prev].q.slerp(a, p.poses[next].q);
        p.poses[g].t = (1 - a) * p.poses[prev].t + a * p.poses[next].t;
        p.state[g] = State::kInterpolated;
        ++interpolated;
      } else {
        p.poses[g] = p.poses[prev < frames ? prev : next];
        p.state[g] = State::kHeld;
        ++held;
      }
    }
    f = next - 1;
  }
}

Status Solver::solve_part(int index) {
  Part& p = parts_[static_cast<std::size_t>(index)];
  if (p.solved) return Ok{};
  const ModelPart& mp = model_.parts[static_cast<std::size_t>(index)];
  PartFit& fit = part_fits_[static_cast<std::size_t>(index)];
  for (std::size_t k = 0; k < mp.points.size(); ++k) {
    if (p.joint_of[k] >= 0 && joint_world_[static_cast<std::size_t>(p.joint_of[k])].empty()) {
      return error("part '" + mp.name + "' is needed before its joint '" + mp.points[k] + "' is found", mp.line);
    }
  }
  if (auto s = calibrate(index); !s) return s;
  const std::size_t frames = m_.frame_count;
  p.poses.assign(frames, Pose{});
  p.state.assign(frames, State::kNone);
  const double outlier = model_.outlier_mm / unit_mm_;
  const double min_spread = 2.0 / unit_mm_;  // 2 mm across the best line
  double sum_sq = 0;
  std::size_t residuals = 0;
  const std::size_t n = mp.points.size();
  PartFitter fitter;
  std::vector<Vector3d> points(n);
  for (std::size_t f = 0; f < frames; ++f) {
    if (n == 2) {
      const int j0 = p.joint_of[0];
      const Part& q = parts_[static_cast<std::size_t>(model_.joints[static_cast<std::size_t>(j0)].part)];
      const Vector3d a = point(p, 0, f), b = point(p, 1, f);
      if (!fit_two_points(p.layout, q.poses[f], a, b, p.poses[f])) continue;
      p.state[f] = State::kFitted;
      const double r = (b - a).norm() - p.layout[1].norm();
      sum_sq += r * r;
      ++residuals;
      continue;
    }
    for (std::size_t k = 0; k < n; ++k) points[k] = point(p, k, f);
    if (!fitter.fit(p.layout, mp.weights, points, p.joint_of, outlier, min_spread, p.poses[f], fit.outliers, sum_sq,
                    residuals)) {
      p.poses[f] = Pose{};
      continue;
    }
    p.state[f] = State::kFitted;
  }
  for (State s : p.state) fit.fitted += s == State::kFitted ? 1 : 0;
  if (fit.fitted == 0) {
    return error("part '" + mp.name + "' cannot be fitted in any frame (fewer than 3 usable points in every frame)",
                 mp.line);
  }
  fit.fit_rms = residuals > 0 ? std::sqrt(sum_sq / static_cast<double>(residuals)) : 0;
  fill(p, fit.interpolated, fit.held);
  p.solved = true;
  return Ok{};
}

Status Solver::place_joint(int index) {
  const ModelJoint& mj = model_.joints[static_cast<std::size_t>(index)];
  JointFit& jf = joint_fits_[static_cast<std::size_t>(index)];
  if (auto s = solve_part(mj.part); !s) return s;
  const Part& p = parts_[static_cast<std::size_t>(mj.part)];
  const std::size_t frames = m_.frame_count;
  // The expression (position or prior) in the part's frame: the median of
  // each coordinate over the frames it can be evaluated in.
  const auto in_part = median_in_part(p.poses, frames, [&](std::size_t f) { return eval(mj.where, f); });
  if (!in_part) {
    return error("joint '" + mj.name + "': its " + (mj.rule == ModelJoint::Rule::kAt ? "position" : "prior") +
                     " needs markers that are never all visible in one frame",
                 mj.line);
  }
  const Vector3d expr_local = *in_part;
  Vector3d local = expr_local;
  if (mj.rule == ModelJoint::Rule::kCentre) {
    jf.functional = true;
    // Sphere fit in the part's frame: every marker y of the child part keeps
    // its distance r_m to the centre c, |y|^2 - 2 y.c = r_m^2 - |c|^2; the
    // unknown right-hand side goes away by centring each marker's samples:
    // 2 (y - mean_m y) . c = |y|^2 - mean_m |y|^2.
    const ModelPart& child = model_.parts[static_cast<std::size_t>(mj.child_part)];
    Matrix3d a = Matrix3d::Zero();
    Vector3d b = Vector3d::Zero();
    std::size_t samples = 0;
    std::vector<std::vector<Vector3d>> per_marker;
    for (std::size_t k = 0; k < child.points.size(); ++k) {
      if (child.point_is_joint[k]) continue;
      const int mi = marker_index_.find(child.points[k])->second;
      std::vector<Vector3d> ys_m;
      for (std::size_t f = 0; f < frames; ++f) {
        if (p.state[f] != State::kFitted) continue;
        const Vector3d w = marker(mi, f);
        if (finite(w)) ys_m.push_back(p.poses[f].local(w));
      }
      if (ys_m.size() < 10) continue;
      Vector3d mean = Vector3d::Zero();
      double mean_sq = 0;
      for (const Vector3d& y : ys_m) {
        mean += y;
        mean_sq += y.squaredNorm();
      }
      mean /= static_cast<double>(ys_m.size());
      mean_sq /= static_cast<double>(ys_m.size());
      for (const Vector3d& y : ys_m) {
        const Vector3d row = 2 * (y - mean);
        a += row * row.transpose();
        b += row * (y.squaredNorm() - mean_sq);
      }
      samples += ys_m.size();
      per_marker.push_back(std::move(ys_m));
    }
    if (samples > 0) {
      Eigen::SelfAdjointEigenSolver<Matrix3d> eig(a);
      const Vector3d lambda = eig.eigenvalues().cwiseMax(0.0);
      const double top = std::sqrt(lambda.maxCoeff() / (4.0 * static_cast<double>(samples)));
      Vector3d c = Vector3d::Zero();
      for (int i = 0; i < 3; ++i) {
        const Vector3d e = eig.eigenvectors().col(i);
        const double spread = std::sqrt(lambda(i) / (4.0 * static_cast<double>(samples)));
        // Eigenvalues come in increasing order: a hinge keeps only column 2.
        const bool determined = spread >= model_.min_spread_mm / unit_mm_ &&
                                spread >= model_.min_relative_spread * top && !(mj.hinge && i < 2);
        if (determined) {
          c += e * (e.dot(b) / lambda(i));
          ++jf.determined;
        } else {
          c += e * e.dot(expr_local);
        }
      }
      local = c;
      double sum_sq = 0;
      std::size_t count = 0;
      for (const std::vector<Vector3d>& ys_m : per_marker) {
        double r = 0;
        for (const Vector3d& y : ys_m) r += (y - c).norm();
        r /= static_cast<double>(ys_m.size());
        for (const Vector3d& y : ys_m) {
          const double d = (y - c).norm() - r;
          sum_sq += d * d;
          ++count;
        }
      }
      jf.fit_rms = std::sqrt(sum_sq / static_cast<double>(count));
    } else {
      warnings_.push_back(error("joint '" + mj.name + "': part '" + child.name +
                                    "' has no marker seen in 10 fitted frames; the joint is at its prior",
                                mj.line));
    }
    jf.prior_distance = (local - expr_local).norm();
  }
  found_local_[static_cast<std::size_t>(index)] = local;
  if (const auto& split = split_local_[static_cast<std::size_t>(index)]) {
    jf.split_shift = (*split - local).norm();
    local = *split;
  }
  joint_local_[static_cast<std::size_t>(index)] = local;
  std::vector<Vector3d>& world = joint_world_[static_cast<std::size_t>(index)];
  world.resize(frames);
  for (std::size_t f = 0; f < frames; ++f) world[f] = p.poses[f].apply(local);
  return Ok{};
}

void Solver::reset() {
  parts_.assign(model_.parts.size(), Part{});
  part_fits_.assign(model_.parts.size(), PartFit{});
  for (std::size_t i = 0; i < model_.parts.size(); ++i) {
    const ModelPart& mp = model_.parts[i];
    part_fits_[i].name = mp.name;
    for (std::size_t k = 0; k < mp.points.size(); ++k) {
      const bool joint = mp.point_is_joint[k];
      parts_[i].joint_of.push_back(joint ? model_.find_joint(mp.points[k]) : -1);
      parts_[i].marker_of.push_back(joint ? -1 : marker_index_.find(mp.points[k])->second);
    }
  }
  joint_fits_.assign(model_.joints.size(), JointFit{});
  joint_world_.assign(model_.joints.size(), {});
  joint_local_.assign(model_.joints.size(), Vector3d::Zero());
  for (std::size_t j = 0; j < model_.joints.size(); ++j) joint_fits_[j].name = model_.joints[j].name;
}

Status Solver::place_all() {
  for (std::size_t j = 0; j < model_.joints.size(); ++j) {
    if (auto s = place_joint(static_cast<int>(j)); !s) return s;
  }
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    if (!parts_[i].solved) {
      if (auto s = solve_part(static_cast<int>(i)); !s) return s;
    }
  }
  return Ok{};
}

// After a pass: each split joint's target in its part, on the line from its
// parent (where the part carries it, the median over the take) through where
// place_joint found it, so that the bone parent -> joint is its fraction of
// the chain's length, that bone plus joint -> end (the median over the take;
// moving the joint along the line changes both). Bone lengths hold whether
// or not the take ever straightens the chain. Placing the joint there moves
// what hangs below it (a part that carries it is fitted again, and the end
// joint with it), so the target moves too: rounds repeat until the joint
// sits within 1e-4 of its bone of its target, each round's step a secant
// step from the last two (plain on the first). A joint the fraction would
// move by more than half its bone keeps where it was found, with a warning.
// True when a joint moved (another round is due); with `apply` false, when
// one would, moving none.
bool Solver::split_chains(bool first_round, bool apply) {
  bool moved = false;
  for (std::size_t j = 0; j < model_.joints.size(); ++j) {
    const ModelJoint& mj = model_.joints[j];
    if (mj.split < 0 || (!first_round && !split_local_[j])) continue;
    const std::vector<Vector3d>& parent = joint_world_[static_cast<std::size_t>(mj.parent)];
    const std::vector<Vector3d>& end = joint_world_[static_cast<std::size_t>(mj.split)];
    const Part& p = parts_[static_cast<std::size_t>(mj.part)];
    const auto parent_in_part = median_in_part(p.poses, m_.frame_count, [&](std::size_t f) { return parent[f]; });
    if (!parent_in_part) continue;
    const Vector3d from = *parent_in_part;
    const Vector3d base = found_local_[j];
    const double bone = (base - from).norm();
    if (!(bone > 0)) continue;
    const Vector3d u = (base - from) / bone;
    // g(s) = (1 - fraction) * upper - fraction * lower with the joint s
    // along the line from where it was found: it rises with s (the upper
    // bone grows, the lower shrinks).
    std::vector<double> lower;
    auto g = [&](double shift) {
      const Vector3d local = base + shift * u;
      lower.clear();
      for (std::size_t f = 0; f < m_.frame_count; ++f) {
        if (finite(end[f])) lower.push_back((end[f] - p.poses[f].apply(local)).norm());
      }
      return (1 - mj.split_fraction) * (local - from).norm() - mj.split_fraction * median(lower);
    };
    double lo = -bone / 2, hi = bone / 2;
    if (!(g(lo) <= 0 && g(hi) >= 0)) {
      if (first_round) {
        char fraction[32];
        std::snprintf(fraction, sizeof fraction, "%g", mj.split_fraction);
        split_warnings_.push_back(error("joint '" + mj.name + "': its split (" + fraction + " of the chain to '" +
                                            model_.joints[static_cast<std::size_t>(mj.split)].name +
                                            "') would move it by more than half its bone; it stays where it was found",
                                        mj.line));
      }
      continue;  // a later round keeps the last place
    }
    for (int i = 0; i < 60 && hi - lo > 1e-9 * bone; ++i) {
      const double mid = (lo + hi) / 2;
      (g(mid) < 0 ? lo : hi) = mid;
    }
    const double target = (lo + hi) / 2;
    const double offset = split_local_[j] ? (*split_local_[j] - base).dot(u) : 0;
    const double gap = target - offset;
    if (std::abs(gap) <= 1e-4 * bone) continue;
    moved = true;
    if (!apply) continue;
    SplitRound& last = split_rounds_[j];
    double next = target;
    if (last.seen && std::abs(gap - last.gap) > 1e-9 * bone) {
      next = offset - gap * (offset - last.offset) / (gap - last.gap);
    }
    last = SplitRound{true, offset, gap};
    split_local_[j] = base + std::clamp(next, -bone / 2, bone / 2) * u;
  }
  return moved;
}

// After split_chains() moved joints: those joints, the parts that carry a
// joint placed again as a point (calibrated and fitted again), the joints
// fixed in such a part or whose expression uses a joint placed again, in the
// model's order (parents, and the joints a part carries, come first). The
// rest of the first pass stands: for cmu41 the shanks and feet are done
// again, not the other 13 parts. Earlier warnings about a joint placed
// again are dropped (this round gives them again).
Status Solver::place_again(std::size_t first_warning) {
  const std::size_t joints = model_.joints.size();
  std::vector<char> again(joints, 0), part_again(parts_.size(), 0);
  auto uses_again = [&](const auto& self, const PointExpr& e) -> bool {
    if (e.kind == PointExpr::Kind::kJoint && again[static_cast<std::size_t>(model_.find_joint(e.name))]) return true;
    return std::any_of(e.args.begin(), e.args.end(), [&](const PointExpr& a) { return self(self, a); });
  };
  for (std::size_t j = 0; j < joints; ++j) {
    const ModelJoint& mj = model_.joints[j];
    if (!split_local_[j] && !part_again[static_cast<std::size_t>(mj.part)] && !uses_again(uses_again, mj.where)) {
      continue;
    }
    again[j] = 1;
    for (std::size_t i = 0; i < parts_.size(); ++i) {
      const std::vector<int>& of = parts_[i].joint_of;
      if (std::find(of.begin(), of.end(), static_cast<int>(j)) != of.end()) part_again[i] = 1;
    }
  }
  std::vector<Error> kept(warnings_.begin(), warnings_.begin() + static_cast<std::ptrdiff_t>(first_warning));
  for (std::size_t w = first_warning; w < warnings_.size(); ++w) {
    bool stale = false;
    for (std::size_t j = 0; j < joints && !stale; ++j) {
      stale = again[j] && warnings_[w].message.rfind("joint '" + model_.joints[j].name + "':", 0) == 0;
    }
    if (!stale) kept.push_back(std::move(warnings_[w]));
  }
  warnings_ = std::move(kept);
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    if (!part_again[i]) continue;
    parts_[i].solved = false;
    part_fits_[i] = PartFit{};
    part_fits_[i].name = model_.parts[i].name;
  }
  for (std::size_t j = 0; j < joints; ++j) {
    if (!again[j]) continue;
    joint_fits_[j] = JointFit{};
    joint_fits_[j].name = model_.joints[j].name;
    joint_world_[j].clear();
    if (auto s = place_joint(static_cast<int>(j)); !s) return s;
  }
  for (std::size_t i = 0; i < parts_.size(); ++i) {
    if (!parts_[i].solved) {
      if (auto s = solve_part(static_cast<int>(i)); !s) return s;
    }
  }
  return Ok{};
}

Result<Motion> Solver::build_motion() {
  const std::size_t frames = m_.frame_count;
  const std::size_t n = model_.joints.size();
  std::vector<Joint> joints(n);
  for (std::size_t j = 0; j < n; ++j) {
    const ModelJoint& mj = model_.joints[j];
    Joint& out = joints[j];
    out.name = mj.name;
    out.parent = mj.parent;
    if (mj.parent < 0) {
      out.channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition,
                      ChannelType::kZrotation, ChannelType::kXrotation, ChannelType::kYrotation};
      continue;
    }
    if (model_.joints[static_cast<std::size_t>(mj.parent)].part != mj.part) {
      out.channels = {ChannelType::kZrotation, ChannelType::kXrotation, ChannelType::kYrotation};
    }
    // t_c: the bone in the joint's frame, averaged over the take.
    const Part& p = parts_[static_cast<std::size_t>(mj.part)];
    const std::vector<Vector3d>& pc = joint_world_[j];
    const std::vector<Vector3d>& pp = joint_world_[static_cast<std::size_t>(mj.parent)];
    Vector3d mean = Vector3d::Zero();
    for (std::size_t f = 0; f < frames; ++f) mean += p.poses[f].local(pc[f]) - p.poses[f].local(pp[f]);
    mean /= static_cast<double>(frames);
    double sum_sq = 0;
    for (std::size_t f = 0; f < frames; ++f) {
      sum_sq += (p.poses[f].local(pc[f]) - p.poses[f].local(pp[f]) - mean).squaredNorm();
    }
    out.offset = mean;
    joint_fits_[j].bone_rms = std::sqrt(sum_sq / static_cast<double>(frames));
    joint_fits_[j].bone_length = mean.norm();
  }
  auto skeleton = Skeleton::create(std::move(joints));
  if (!skeleton) return skeleton.error();
  Motion motion;
  motion.skeleton = std::move(*skeleton);
  motion.convention = Convention::kPreRotation;
  motion.frame_time = m_.frame_rate > 0 ? 1.0 / m_.frame_rate : 0.0;
  motion.frame_count = frames;
  motion.values.assign(frames * motion.stride(), 0.0);
  std::vector<Vector3d> previous(n, Vector3d::Zero());
  std::vector<Quaterniond> part_q(parts_.size(), Quaterniond::Identity());
  std::vector<Vector3d> world(n);
  for (std::size_t f = 0; f < frames; ++f) {
    for (std::size_t i = 0; i < parts_.size(); ++i) {
      if (!parts_[i].poses.empty()) part_q[i] = parts_[i].poses[f].q;
    }
    for (std::size_t j = 0; j < n; ++j) world[j] = joint_world_[j][f];
    write_frame(motion.skeleton, model_, part_q, world, previous, f == 0, motion.frame(f));
  }
  if (auto s = motion.validate(); !s) return s.error();
  return motion;
}

void Solver::report_motion(MarkerSolveResult& r) const {
  const std::size_t parts = model_.parts.size();
  std::vector<double> sum_sq(parts, 0), max(parts, 0);
  std::vector<std::size_t> count(parts, 0);
  std::vector<Vector3d> positions(r.motion.skeleton.size());
  std::vector<Matrix3d> orientations(r.motion.skeleton.size());
  for (std::size_t f = 0; f < r.motion.frame_count; ++f) {
    compute_frame(r.motion, f, positions, orientations);
    for (const CarriedMarker& c : r.carried) {
      const Vector3d measured = marker(c.marker_index, f);
      if (!finite(measured)) continue;
      const std::size_t j = static_cast<std::size_t>(c.joint);
      const double d = (positions[j] + orientations[j] * c.offset - measured).norm();
      const std::size_t p = static_cast<std::size_t>(c.part);
      sum_sq[p] += d * d;
      max[p] = std::max(max[p], d);
      ++count[p];
    }
  }
  for (std::size_t p = 0; p < parts; ++p) {
    r.parts[p].motion_rms = count[p] > 0 ? std::sqrt(sum_sq[p] / static_cast<double>(count[p])) : kNaN;
    r.parts[p].motion_max = count[p] > 0 ? max[p] : kNaN;
  }
}

Result<MarkerSolveResult> Solver::run(const MarkerSolveOptions& options) {
  if (auto s = m_.validate(); !s) return s.error();
  if (m_.frame_count == 0) return make_error(ErrorKind::kInvalidData, "the marker file has no frames");
  unit_mm_ = millimetres_per_marker_unit(m_.units);
  if (!(unit_mm_ > 0)) {
    return make_error(ErrorKind::kInvalidData,
                      "the marker file's units '" + m_.units + "' are not a length (expected mm, cm, m or in)");
  }
  if (m_.units.empty()) warnings_.push_back(make_error("the marker file gives no units: millimetres assumed"));
  if (auto s = resolve_markers(); !s) return s.error();
  std::vector<int> roots;
  for (const std::string& name : options.roots) {
    const int j = model_.find_joint(name);
    if (j < 0)
      return make_error(ErrorKind::kNotFound, "unknown joint '" + name + "' (not in marker model " + model_.name + ")");
    roots.push_back(j);
  }
  // Splits need the whole chain found: a first pass finds every joint, then
  // the split joints move and what depends on them is placed again.
  found_local_.assign(model_.joints.size(), Vector3d::Zero());
  split_local_.assign(model_.joints.size(), std::nullopt);
  split_rounds_.assign(model_.joints.size(), SplitRound{});
  const std::size_t warnings_before = warnings_.size();
  reset();
  if (auto s = place_all(); !s) return s.error();
  constexpr int kMaxSplitRounds = 10;
  int round = 0;
  for (; round < kMaxSplitRounds && split_chains(round == 0, true); ++round) {
    if (auto s = place_again(warnings_before); !s) return s.error();
  }
  if (round == kMaxSplitRounds && split_chains(false, false)) {
    split_warnings_.push_back(error("the splits had not settled after " + std::to_string(kMaxSplitRounds) +
                                    " rounds; their joints stay where the last round put them"));
  }
  warnings_.insert(warnings_.end(), split_warnings_.begin(), split_warnings_.end());
  auto motion = build_motion();
  if (!motion) return motion.error();
  MarkerSolveResult r;
  r.motion = std::move(*motion);
  r.parts = part_fits_;
  r.joints = joint_fits_;
  r.millimetres_per_unit = unit_mm_;
  // Each part's markers ride on the first joint fixed in that part.
  for (std::size_t i = 0; i < model_.parts.size(); ++i) {
    int carrier = -1;
    for (std::size_t j = 0; j < model_.joints.size() && carrier < 0; ++j) {
      if (model_.joints[j].part == static_cast<int>(i)) carrier = static_cast<int>(j);
    }
    if (carrier < 0) continue;
    const ModelPart& mp = model_.parts[i];
    for (std::size_t k = 0; k < mp.points.size(); ++k) {
      if (mp.point_is_joint[k]) continue;
      CarriedMarker c;
      c.marker = mp.points[k];
      c.marker_index = parts_[i].marker_of[k];
      c.joint = carrier;
      c.part = static_cast<int>(i);
      c.offset = parts_[i].layout[k] - joint_local_[static_cast<std::size_t>(carrier)];
      r.carried.push_back(std::move(c));
    }
  }
  report_motion(r);
  if (!roots.empty()) {
    auto rooted = set_roots(r.motion, roots);
    if (!rooted) return rooted.error();
    r.motion = std::move(*rooted);
    r.carried.clear();  // they ride on the model's tree; see the header
  }
  r.warnings = std::move(warnings_);
  return r;
}

}  // namespace

namespace marker_detail {

using Eigen::Matrix3d;
using Eigen::Quaterniond;
using Eigen::Vector3d;

bool PartFitter::fit(const std::vector<Vector3d>& layout, const std::vector<double>& point_weights,
                     const std::vector<Vector3d>& points, const std::vector<int>& joint_of, double outlier,
                     double min_spread, Pose& pose, std::size_t& outliers, double& sum_sq, std::size_t& residuals) {
  which.clear();
  for (std::size_t k = 0; k < points.size(); ++k) {
    if (finite(points[k])) which.push_back(k);
  }
  bool ok = false;
  while (which.size() >= 3) {
    local.clear();
    world.clear();
    weights.clear();
    for (std::size_t k : which) {
      local.push_back(layout[k]);
      world.push_back(points[k]);
      weights.push_back(point_weights[k]);
    }
    ok = fit_rigid(local, world, weights, min_spread, pose);
    if (!ok) break;
    std::size_t worst = 0;
    double worst_r = -1;
    for (std::size_t i = 0; i < which.size(); ++i) {
      const double r = (pose.apply(local[i]) - world[i]).norm();
      if (r > worst_r) {
        worst_r = r;
        worst = i;
      }
    }
    // A joint is never the outlier: it is carried exactly by another part.
    if (worst_r <= outlier || which.size() == 3 || joint_of[which[worst]] >= 0) break;
    which.erase(which.begin() + static_cast<std::ptrdiff_t>(worst));
    ++outliers;
  }
  if (!ok) return false;
  for (std::size_t i = 0; i < which.size(); ++i) {
    sum_sq += (pose.apply(local[i]) - world[i]).squaredNorm();
    ++residuals;
  }
  return true;
}

// A 2-point part (a joint of another part, then a marker) in one frame: the
// other part's pose turned so that the layout's direction meets the marker,
// at the joint. False when the marker is missing or on the joint.
bool fit_two_points(const std::vector<Vector3d>& layout, const Pose& other, const Vector3d& joint,
                    const Vector3d& marker, Pose& pose) {
  const Vector3d d = marker - joint;
  if (!finite(d) || !(d.norm() > 0)) return false;
  const Vector3d rest = other.q * layout[1].normalized();
  pose.q = (Quaterniond::FromTwoVectors(rest, d.normalized()) * other.q).normalized();
  pose.t = joint;
  return true;
}

// One frame's channel values of the model's motion from each part's world
// rotation and each joint's world position: roots their position, then
// rotations relative to the parent joint's part, as Z X Y Euler angles (the
// previous frame's, when given, pick the nearest equivalent).
void write_frame(const Skeleton& skeleton, const MarkerModel& model, const std::vector<Quaterniond>& part_q,
                 const std::vector<Vector3d>& joint_world, std::vector<Vector3d>& previous, bool first,
                 std::span<double> values) {
  static constexpr Axis kOrder[3] = {Axis::kZ, Axis::kX, Axis::kY};
  for (std::size_t j = 0; j < model.joints.size(); ++j) {
    const Joint& joint = skeleton.joint(static_cast<int>(j));
    if (joint.channels.empty()) continue;
    const ModelJoint& mj = model.joints[j];
    Matrix3d r = part_q[static_cast<std::size_t>(mj.part)].toRotationMatrix();
    std::size_t c = static_cast<std::size_t>(skeleton.channel_offset(static_cast<int>(j)));
    if (mj.parent < 0) {
      for (int axis = 0; axis < 3; ++axis) values[c++] = joint_world[j](axis);
    } else {
      const int parent_part = model.joints[static_cast<std::size_t>(mj.parent)].part;
      r = part_q[static_cast<std::size_t>(parent_part)].toRotationMatrix().transpose() * r;
    }
    const Vector3d angles = decompose_euler(r, kOrder, first ? nullptr : &previous[j]);
    previous[j] = angles;
    for (int k = 0; k < 3; ++k) values[c++] = angles(k);
  }
}

Result<MarkerSolveResult> solve_keeping(const MarkerTrajectories& markers, const MarkerModel& model,
                                        std::vector<FramePart>& parts, std::vector<Vector3d>& joint_local) {
  Solver solver(markers, model);
  auto solved = solver.run({});
  if (solved) solver.keep(parts, joint_local);
  return solved;
}

}  // namespace marker_detail

Result<MarkerSolveResult> solve_markers(const MarkerTrajectories& markers, const MarkerModel& model,
                                        const MarkerSolveOptions& options) {
  return Solver(markers, model).run(options);
}

std::vector<Vector3d> carried_marker_positions(const Motion& motion, const std::vector<CarriedMarker>& carried,
                                               std::size_t f) {
  std::vector<Vector3d> positions(motion.skeleton.size());
  std::vector<Matrix3d> orientations(motion.skeleton.size());
  compute_frame(motion, f, positions, orientations);
  std::vector<Vector3d> out;
  out.reserve(carried.size());
  for (const CarriedMarker& c : carried) {
    const std::size_t j = static_cast<std::size_t>(c.joint);
    out.push_back(positions[j] + orientations[j] * c.offset);
  }
  return out;
}

double millimetres_per_marker_unit(std::string_view units) {
  std::string u;
  for (char c : units) u += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (u.empty() || u == "mm") return 1;
  if (u == "cm") return 10;
  if (u == "m") return 1000;
  if (u == "in") return 25.4;
  return 0;
}

}  // namespace gmr
