#include "gmr/retarget/retarget.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <string>

#include "gmr/core/rotation.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/convert.h"
#include "rig_joints.h"

namespace gmr {
namespace {

using Mat = Eigen::Matrix3d;
using Vec = Eigen::Vector3d;

// The rest pose: every rotation zero, every position channel at its offset
// (a BVH position channel replaces the offset, so zero would fold the joint
// onto its parent).
Motion rest_motion(const Skeleton& skeleton, Convention convention) {
  Motion m;
  m.skeleton = skeleton;
  m.convention = convention;
  m.frame_time = 1.0;
  m.frame_count = 1;
  m.values.assign(m.stride(), 0.0);
  for (int j = 0; j < static_cast<int>(skeleton.size()); ++j) {
    const Joint& joint = skeleton.joint(j);
    for (std::size_t c = 0; c < joint.channels.size(); ++c) {
      if (is_position(joint.channels[c])) {
        m.values[static_cast<std::size_t>(skeleton.channel_offset(j)) + c] =
            joint.offset[static_cast<int>(axis_of(joint.channels[c]))];
      }
    }
  }
  return m;
}

void positions_and_frames(const Motion& m, std::size_t f, std::vector<Vec>& p, std::vector<Mat>& w) {
  p.resize(m.skeleton.size());
  w.resize(m.skeleton.size());
  compute_frame(m, f, p, w);
}

// The pose a rig is measured in, with its channel values.
struct Reference {
  std::vector<double> values;
  std::vector<Vec> p;
  std::vector<Mat> w;
  std::string what;
};

// Head above the hips, both feet well below them, the hips apart.
bool stands(const HumanoidMap& m, const std::vector<Vec>& p) {
  auto at = [&](Role r) { return p[static_cast<std::size_t>(m[r])]; };
  const Vec up = at(Role::kHead) - at(Role::kHips);
  const double height = up.norm();
  if (height < 1e-9) return false;
  const Vec u = up / height;
  const double left = (at(Role::kLeftFoot) - at(Role::kHips)).dot(u);
  const double right = (at(Role::kRightFoot) - at(Role::kHips)).dot(u);
  const Vec hips = at(Role::kLeftUpperLeg) - at(Role::kRightUpperLeg);
  return left < -0.5 * height && right < -0.5 * height && (hips - hips.dot(u) * u).norm() > 0.05 * height;
}

Result<Reference> reference_pose(const Motion& m, const HumanoidMap& map, const char* which) {
  Reference r;
  const Motion rest = rest_motion(m.skeleton, m.convention);
  positions_and_frames(rest, 0, r.p, r.w);
  if (stands(map, r.p)) {
    r.values = rest.values;
    r.what = "rest pose";
    return r;
  }
  if (m.frame_count > 0) {
    positions_and_frames(m, 0, r.p, r.w);
    if (stands(map, r.p)) {
      const auto first = m.frame(0);
      r.values.assign(first.begin(), first.end());
      r.what = "first frame";
      return r;
    }
  }
  return make_error(std::string("the ") + which +
                    "'s rest pose does not stand like a humanoid (head above hips, feet below, hips apart)" +
                    (m.frame_count > 0 ? " and neither does its first frame" : " and it has no frame that could"));
}

Mat swing(const Vec& from, const Vec& to) {
  if (from.squaredNorm() < 1e-24 || to.squaredNorm() < 1e-24) return Mat::Identity();
  return Eigen::Quaterniond::FromTwoVectors(from, to).toRotationMatrix();
}

// Columns: left (made orthogonal to up), up, forward (left x up).
Mat body_frame(const Vec& up, const Vec& left) {
  const Vec y = up.normalized();
  const Vec x = (left - left.dot(y) * y).normalized();
  Mat f;
  f.col(0) = x;
  f.col(1) = y;
  f.col(2) = x.cross(y);
  return f;
}

// Each column replaced by the nearest signed axis when within 30 degrees of
// it; the frame as it was when the result is not a rotation.
Mat snapped(const Mat& f) {
  Mat s = Mat::Zero();
  for (int c = 0; c < 3; ++c) {
    int k = 0;
    f.col(c).cwiseAbs().maxCoeff(&k);
    if (std::abs(f(k, c)) < std::cos(30.0 * M_PI / 180.0)) return f;
    s(k, c) = f(k, c) > 0 ? 1.0 : -1.0;
  }
  return std::abs(s.determinant() - 1.0) < 1e-9 ? s : f;
}

// The joint after `a` on the tree path from `a` to `b` (same tree, a != b):
// a child of `a` when `b` is below it, else its parent (a re-rooted view
// holds limbs upside down).
int next_on_path(const Skeleton& s, int a, int b) {
  if (!detail::below(s, a, b)) return s.joint(a).parent;
  int k = b;
  while (s.joint(k).parent != a) k = s.joint(k).parent;
  return k;
}

// The joint whose W turns the edge between neighbours a and n: in pre-rotation
// the edge's child end (W_j is the frame of the bone p(j) -> j), in
// post-rotation its parent end (W_p turns the offsets of p's children). An
// edge keeps its frame whichever end a view roots it at.
int edge_frame(const Skeleton& s, Convention convention, int a, int n) {
  const bool down = s.joint(n).parent == a;
  const int child = down ? n : a, parent = down ? a : n;
  return convention == Convention::kPreRotation ? child : parent;
}

// A bone of both rigs between two roles: the target's joint a_t turns so that
// its rest direction (to b_t) points where the source's a_s -> b_s does.
struct Segment {
  Role from, to;
  int a_t, b_t, a_s, b_s;
  int frame_s;       // the source joint whose W turns the bone a_s -> (next joint)
  Vec rest_t;        // a_t -> b_t in a_t's frame at the target's reference, unit
  Mat tpose_t;       // a_t's world orientation with the bone along the source's reference direction
  Mat rest_frame_s;  // W of frame_s at the source's rest
};

constexpr std::array<std::array<Role, 7>, 1> kSpine = {
    {{Role::kHips, Role::kSpine, Role::kChest, Role::kUpperChest, Role::kNeck, Role::kHead, Role::kHeadEnd}}};
constexpr std::array<std::array<Role, 5>, 4> kLimbs = {{
    {Role::kLeftShoulder, Role::kLeftUpperArm, Role::kLeftLowerArm, Role::kLeftHand, Role::kLeftHandEnd},
    {Role::kRightShoulder, Role::kRightUpperArm, Role::kRightLowerArm, Role::kRightHand, Role::kRightHandEnd},
    {Role::kLeftUpperLeg, Role::kLeftLowerLeg, Role::kLeftFoot, Role::kLeftToes, Role::kLeftToesEnd},
    {Role::kRightUpperLeg, Role::kRightLowerLeg, Role::kRightFoot, Role::kRightToes, Role::kRightToesEnd},
}};

struct Plan {
  RetargetPlan report;
  Reference source_ref, target_ref;
  std::vector<Segment> segments;
  int hips_t = kNoParent, hips_s = kNoParent;
  int up_t = kNoParent, up_s = kNoParent;  // the first spine-chain role after the hips both rigs have
  Vec hips_up_rest, hips_left_rest;        // target reference vectors the hips' two-vector fit starts from
  Mat hips_rest_frame;                     // the hips' world orientation at the reference
  int root_t = kNoParent;                  // the root of the target tree holding the hips
  Vec root_to_hips;                        // at the reference
};

double hip_height(const HumanoidMap& m, const std::vector<Vec>& p, const Vec& up) {
  double lowest = up.dot(p[static_cast<std::size_t>(m[Role::kHips])]);
  for (Role r : {Role::kLeftFoot, Role::kRightFoot, Role::kLeftToes, Role::kRightToes, Role::kLeftToesEnd,
                 Role::kRightToesEnd}) {
    if (m.has(r)) lowest = std::min(lowest, up.dot(p[static_cast<std::size_t>(m[r])]));
  }
  return up.dot(p[static_cast<std::size_t>(m[Role::kHips])]) - lowest;
}

Result<Plan> make_plan(const Motion& source_motion, const Motion& target_motion, const RetargetOptions& options) {
  Plan plan;
  const Skeleton& source = source_motion.skeleton;
  const Skeleton& target = target_motion.skeleton;
  const Convention source_convention = source_motion.convention;
  auto sm = map_humanoid(source, options.source_map);
  if (!sm.ok()) return make_error("the source: " + sm.error().message);
  auto tm = map_humanoid(target, options.target_map);
  if (!tm.ok()) return make_error("the target rig: " + tm.error().message);
  plan.report.source = *sm;
  plan.report.target = *tm;
  const HumanoidMap& S = *sm;
  const HumanoidMap& T = *tm;

  auto sr = reference_pose(source_motion, S, "source");
  if (!sr.ok()) return sr.error();
  auto tr = reference_pose(target_motion, T, "target");
  if (!tr.ok()) return tr.error();
  plan.source_ref = std::move(sr).value();
  plan.target_ref = std::move(tr).value();
  plan.report.source_reference = plan.source_ref.what;
  plan.report.target_reference = plan.target_ref.what;
  const std::vector<Vec>& ps = plan.source_ref.p;
  const std::vector<Mat>& ws = plan.source_ref.w;
  const std::vector<Vec>& pt = plan.target_ref.p;
  const std::vector<Mat>& wt = plan.target_ref.w;
  auto at = [](const std::vector<Vec>& p, int j) { return p[static_cast<std::size_t>(j)]; };

  // World axes: rest up (hips -> head) and left (right -> left hip) of each.
  const Vec up_s = at(ps, S[Role::kHead]) - at(ps, S[Role::kHips]);
  const Vec up_t = at(pt, T[Role::kHead]) - at(pt, T[Role::kHips]);
  const Vec left_s = at(ps, S[Role::kLeftUpperLeg]) - at(ps, S[Role::kRightUpperLeg]);
  const Vec left_t = at(pt, T[Role::kLeftUpperLeg]) - at(pt, T[Role::kRightUpperLeg]);
  if (up_s.norm() < 1e-9 || up_t.norm() < 1e-9 || left_s.norm() < 1e-9 || left_t.norm() < 1e-9) {
    return make_error("a rig's rest pose has its head on its hips or both hips in one place: no body axes");
  }
  const Mat G = snapped(body_frame(up_t, left_t)) * snapped(body_frame(up_s, left_s)).transpose();
  plan.report.axes = G;
  const double hs = hip_height(S, ps, up_s.normalized()), ht = hip_height(T, pt, up_t.normalized());
  plan.report.scale = hs > 1e-9 && ht > 1e-9 ? ht / hs : 1.0;
  plan.report.target_up = snapped(body_frame(up_t, left_t)).col(1);
  plan.report.target_hip_height = ht;

  auto add_segment = [&](Role from, Role to) -> Status {
    Segment g{from, to, T[from], T[to], S[from], S[to], kNoParent, {}, {}, {}};
    // The rig turns a_t to move b_t, so b_t must hang below it; the source
    // only needs a path between them (a re-rooted view may hang a leg from
    // its foot).
    auto refuse = [&](const Skeleton& rig, int a, int b, const char* name, const char* relation) {
      return make_error(std::string("the ") + name + "'s " + std::string(role_name(to)) + " joint '" +
                        rig.joint(b).name + "' is not " + relation + " its " + std::string(role_name(from)) +
                        " joint '" + rig.joint(a).name + "'");
    };
    if (g.a_t == g.b_t || !detail::below(target, g.a_t, g.b_t)) return refuse(target, g.a_t, g.b_t, "target", "below");
    if (g.a_s == g.b_s || source.root_of(g.a_s) != source.root_of(g.b_s)) {
      return refuse(source, g.a_s, g.b_s, "source", "in the tree of");
    }
    g.frame_s = edge_frame(source, source_convention, g.a_s, next_on_path(source, g.a_s, g.b_s));
    const Mat& frame_t = wt[static_cast<std::size_t>(g.a_t)];
    const Vec rest_t = frame_t.transpose() * (at(pt, g.b_t) - at(pt, g.a_t));
    const Vec rest_s = G * (at(ps, g.b_s) - at(ps, g.a_s));
    if (rest_t.norm() < 1e-9 || rest_s.norm() < 1e-9) return Ok{};  // a zero-length bone drives nothing
    g.rest_t = rest_t.normalized();
    g.tpose_t = swing(frame_t * g.rest_t, rest_s.normalized()) * frame_t;
    g.rest_frame_s = ws[static_cast<std::size_t>(g.frame_s)];
    plan.segments.push_back(g);
    plan.report.driven.push_back(target.joint(g.a_t).name + " (" + std::string(role_name(from)) + " -> " +
                                 std::string(role_name(to)) + ")");
    return Ok{};
  };
  // The spine from the first role after the hips (the hips are fitted to two
  // vectors below), then each limb; roles only one rig has are skipped.
  std::vector<Role> spine;
  for (Role r : kSpine[0]) {
    if (S.has(r) && T.has(r)) spine.push_back(r);
  }
  for (std::size_t i = 1; i + 1 < spine.size(); ++i) {
    if (auto s = add_segment(spine[i], spine[i + 1]); !s.ok()) return s.error();
  }
  for (const auto& limb : kLimbs) {
    std::vector<Role> common;
    for (Role r : limb) {
      if (S.has(r) && T.has(r)) common.push_back(r);
    }
    for (std::size_t i = 0; i + 1 < common.size(); ++i) {
      if (auto s = add_segment(common[i], common[i + 1]); !s.ok()) return s.error();
    }
  }
  plan.hips_t = T[Role::kHips];
  plan.hips_s = S[Role::kHips];
  plan.up_t = T[spine.size() > 1 ? spine[1] : Role::kHead];
  plan.up_s = S[spine.size() > 1 ? spine[1] : Role::kHead];
  plan.hips_up_rest = at(pt, plan.up_t) - at(pt, plan.hips_t);
  plan.hips_rest_frame = wt[static_cast<std::size_t>(plan.hips_t)];
  plan.hips_left_rest = left_t;
  plan.report.driven.insert(plan.report.driven.begin(), target.joint(plan.hips_t).name + " (hips: up and left)");
  plan.root_t = target.root_of(plan.hips_t);
  plan.root_to_hips = at(pt, plan.hips_t) - at(pt, plan.root_t);
  return plan;
}

// The output skeleton: the target's, with three rotation channels on every
// driven joint that had fewer (Z X Y added in that order, the rig's own
// rotation channels kept first).
Result<Skeleton> make_output_skeleton(const Skeleton& target, const std::vector<bool>& driven) {
  std::vector<Joint> joints = target.joints();
  for (std::size_t j = 0; j < joints.size(); ++j) {
    if (!driven[j]) continue;
    auto& ch = joints[j].channels;
    for (Axis a : {Axis::kZ, Axis::kX, Axis::kY}) {
      if (std::find(ch.begin(), ch.end(), rotation_channel(a)) == ch.end()) ch.push_back(rotation_channel(a));
    }
  }
  return Skeleton::create(std::move(joints));
}

}  // namespace

Result<RetargetPlan> plan_retarget(const Motion& source, const Motion& target, const RetargetOptions& options) {
  auto plan = make_plan(source, target, options);
  if (!plan.ok()) return plan.error();
  return plan->report;
}

// What a Retargeter keeps between calls: the plan and everything per joint
// that does not change with the frame.
struct Retargeter::State {
  Plan plan;
  Skeleton source_skeleton;
  Convention source_convention = Convention::kPostRotation;
  Skeleton target;  // the rig, post-rotation
  Skeleton out;     // the rig with the channels driven joints need
  std::vector<int> segment_of;
  std::vector<bool> driven;
  std::vector<double> reference;     // per output channel
  std::vector<Mat> reference_local;  // per joint
  Mat hips_rest;
};

Result<Retargeter> Retargeter::make(const Motion& source, const Motion& target_rig, const RetargetOptions& options) {
  auto post = to_post_rotation(target_rig);
  if (!post.ok()) return post.error();
  if (post->skeleton.size() != target_rig.skeleton.size()) {
    return make_error(
        "the target rig is a pre-rotation motion whose joints' children turn apart: as post-rotation it "
        "would need joints it does not have; give the rig as BVH");
  }
  auto planned = make_plan(source, *post, options);
  if (!planned.ok()) return planned.error();
  auto st = std::make_shared<State>();
  st->plan = std::move(planned).value();
  st->source_skeleton = source.skeleton;
  st->source_convention = source.convention;
  st->target = post->skeleton;
  const Plan& plan = st->plan;
  const Skeleton& target = st->target;
  const std::size_t n = target.size();
  st->segment_of.assign(n, -1);
  st->driven.assign(n, false);
  for (std::size_t i = 0; i < plan.segments.size(); ++i) {
    const auto a = static_cast<std::size_t>(plan.segments[i].a_t);
    if (st->segment_of[a] < 0) st->segment_of[a] = static_cast<int>(i);  // one bone per joint: the first chain's
    st->driven[a] = true;
  }
  st->driven[static_cast<std::size_t>(plan.hips_t)] = true;
  auto skeleton = make_output_skeleton(target, st->driven);
  if (!skeleton.ok()) return skeleton.error();
  st->out = std::move(skeleton).value();
  // The reference values, moved to the output's channel slots (added channels start at 0).
  st->reference.assign(static_cast<std::size_t>(st->out.channel_count()), 0.0);
  for (int j = 0; j < static_cast<int>(n); ++j) {
    const Joint& from = target.joint(j);
    const Joint& to = st->out.joint(j);
    for (std::size_t c = 0; c < from.channels.size(); ++c) {
      const auto k = std::find(to.channels.begin(), to.channels.end(), from.channels[c]) - to.channels.begin();
      st->reference[static_cast<std::size_t>(st->out.channel_offset(j) + k)] =
          plan.target_ref.values[static_cast<std::size_t>(target.channel_offset(j)) + c];
    }
  }
  // Undriven joints keep their reference local rotation.
  st->reference_local.resize(n);
  for (int j = 0; j < static_cast<int>(n); ++j) {
    const int parent = target.joint(j).parent;
    const Mat& w = plan.target_ref.w[static_cast<std::size_t>(j)];
    st->reference_local[static_cast<std::size_t>(j)] =
        parent == kNoParent ? w : Mat(plan.target_ref.w[static_cast<std::size_t>(parent)].transpose() * w);
  }
  st->hips_rest = body_frame(plan.hips_up_rest, plan.hips_left_rest);
  Retargeter r;
  r.state_ = std::move(st);
  return r;
}

const RetargetPlan& Retargeter::plan() const { return state_->plan.report; }

bool Retargeter::fits(const Motion& source) const {
  if (!state_) return false;
  const Skeleton& a = state_->source_skeleton;
  const Skeleton& b = source.skeleton;
  if (source.convention != state_->source_convention || a.size() != b.size()) return false;
  if (a.shares(b)) return true;  // a live source's frames: copies of its skeleton
  for (int j = 0; j < static_cast<int>(a.size()); ++j) {
    const Joint &x = a.joint(j), &y = b.joint(j);
    if (x.name != y.name || x.parent != y.parent || x.offset != y.offset || x.channels != y.channels) return false;
  }
  return true;
}

const Skeleton& Retargeter::output_skeleton() const { return state_->out; }

Result<Motion> Retargeter::apply(const Motion& source) const {
  auto values = apply_values(source);
  if (!values.ok()) return values.error();
  Motion out;
  out.skeleton = state_->out;
  out.convention = Convention::kPostRotation;
  out.frame_time = source.frame_time;
  out.frame_count = source.frame_count;
  out.values = std::move(values).value();
  if (auto s = out.validate(); !s.ok()) return s.error();
  return out;
}

Result<std::vector<double>> Retargeter::apply_values(const Motion& source) const {
  if (auto s = source.validate(); !s.ok()) return s.error();
  if (!fits(source)) return make_error("retarget: the motion is not on the skeleton the retargeter was made for");
  const State& st = *state_;
  const Plan& plan = st.plan;
  const Skeleton& target = st.target;
  const Skeleton& out_skeleton = st.out;
  const Mat& G = plan.report.axes;
  const std::size_t n = target.size();
  const auto stride = static_cast<std::size_t>(out_skeleton.channel_count());
  std::vector<double> out_values(source.frame_count * stride);

  std::vector<Vec> ps;
  std::vector<Mat> ws, wt(n);
  std::vector<Vec> hint(n, Vec::Zero());
  auto at = [&](int j) { return ps[static_cast<std::size_t>(j)]; };
  const HumanoidMap& S = plan.report.source;
  for (std::size_t f = 0; f < source.frame_count; ++f) {
    positions_and_frames(source, f, ps, ws);
    const std::span<double> values(out_values.data() + f * stride, stride);
    std::copy(st.reference.begin(), st.reference.end(), values.begin());
    for (int j = 0; j < static_cast<int>(n); ++j) {
      const auto k = static_cast<std::size_t>(j);
      const int parent = target.joint(j).parent;
      const Mat parent_w = parent == kNoParent ? Mat::Identity() : wt[static_cast<std::size_t>(parent)];
      Mat w = parent_w * st.reference_local[k];
      if (j == plan.hips_t) {
        const Vec up = G * (at(plan.up_s) - at(plan.hips_s));
        const Vec left = G * (at(S[Role::kLeftUpperLeg]) - at(S[Role::kRightUpperLeg]));
        w = body_frame(up, left) * st.hips_rest.transpose() * plan.hips_rest_frame;
      } else if (st.segment_of[k] >= 0) {
        const Segment& g = plan.segments[static_cast<std::size_t>(st.segment_of[k])];
        const Mat d = G * ws[static_cast<std::size_t>(g.frame_s)] * g.rest_frame_s.transpose() * G.transpose();
        const Mat predicted = d * g.tpose_t;
        const Vec want = G * (at(g.b_s) - at(g.a_s));
        w = swing(predicted * g.rest_t, want) * predicted;
      }
      wt[k] = w;
      if (!st.driven[k]) continue;
      // The rotation channels, in the joint's order, continuous with the last frame.
      const Mat local = parent_w.transpose() * w;
      Axis order[3];
      int slots[3];
      detail::rotation_slots(out_skeleton, j, order, slots);  // a driven joint has three
      const Vec angles = decompose_euler(local, order, f == 0 ? nullptr : &hint[k]);
      hint[k] = angles;
      for (int i = 0; i < 3; ++i) values[static_cast<std::size_t>(slots[i])] = angles[i];
    }
    // The root travels the source's hips path, scaled, with the hips over it.
    // (The joints from the root to the hips keep their reference rotations,
    // so the hips sit at a fixed offset from the root unless the root is the hips.)
    const Vec hips = plan.report.scale * (G * at(plan.hips_s));
    const Vec root = plan.root_t == plan.hips_t ? hips : Vec(hips - plan.root_to_hips);
    const Joint& root_joint = out_skeleton.joint(plan.root_t);
    for (std::size_t c = 0; c < root_joint.channels.size(); ++c) {
      if (is_position(root_joint.channels[c])) {
        values[static_cast<std::size_t>(out_skeleton.channel_offset(plan.root_t)) + c] =
            root[static_cast<int>(axis_of(root_joint.channels[c]))];
      }
    }
  }
  for (std::size_t k = 0; k < out_values.size(); ++k) {
    if (!std::isfinite(out_values[k])) {
      return make_error("retarget: frame " + std::to_string(k / std::max<std::size_t>(stride, 1)) +
                        " gives a value that is not finite (a degenerate pose)");
    }
  }
  return out_values;
}

Result<Motion> retarget(const Motion& source, const Motion& target, const RetargetOptions& options,
                        RetargetPlan* plan_out) {
  if (auto s = source.validate(); !s.ok()) return s.error();
  auto r = Retargeter::make(source, target, options);
  if (!r.ok()) return r.error();
  if (plan_out != nullptr) *plan_out = r->plan();
  return r->apply(source);
}

}  // namespace gmr
