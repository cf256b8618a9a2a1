#include "gmr/fast/fast_fk.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

#include "fast/fk_kernels.h"

namespace gmr::fast {
namespace {

constexpr float kIdentity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};

// Rotation channels computed per frame, rounded up to kFrameAlignment.
std::size_t padded_rotations(const CompiledMotion& m) { return m.rotation_gather_offsets().size(); }

// The workspace span may start anywhere; the kernels want 64-byte alignment,
// which fk_workspace_size() leaves room for.
float* aligned(std::span<float> ws) {
  auto addr = reinterpret_cast<std::uintptr_t>(ws.data());
  addr = (addr + 63) & ~static_cast<std::uintptr_t>(63);
  return reinterpret_cast<float*>(addr);
}

std::size_t range_scratch(const CompiledMotion& m) {
  return (m.slot_count() * 9 + m.joint_count() * 3) * kFrameAlignment;
}

// Angles, sines, cosines, then 12 floats per slot (the SIMD frame kernel keeps
// 4-float columns; the scalar chain uses 9) and 4 per joint position.
std::size_t frame_scratch(const CompiledMotion& m) {
  return 3 * padded_rotations(m) + m.slot_count() * 12 + m.joint_count() * 4;
}

inline void mat_mul(const float* a, const float* b, float* out) {
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) out[3 * r + c] = a[3 * r] * b[c] + a[3 * r + 1] * b[3 + c] + a[3 * r + 2] * b[6 + c];
  }
}

// m <- m * R_axis: see ApplyAxis in fk_kernels.cpp.
inline void apply_axis(int axis, float* m, float c, float s) {
  const int u = (axis + 1) % 3;
  const int v = (axis + 2) % 3;
  for (int i = 0; i < 3; ++i) {
    const float mu = m[3 * i + u];
    const float mv = m[3 * i + v];
    m[3 * i + u] = c * mu + s * mv;
    m[3 * i + v] = c * mv - s * mu;
  }
}

// One frame, one joint after the other, from precomputed sines and cosines of
// every rotation channel (joint order). `world` holds slot_count() matrices.
void frame_chain(const CompiledMotion& m, std::size_t f, const float* sines, const float* cosines, float* world,
                 float* out_pos, float* out_ori) {
  const bool pre = m.convention() == Convention::kPreRotation;
  const bool want_world = out_ori != nullptr;
  const bool positions = out_pos != nullptr && !m.all_roots();
  const auto plans = joint_plans(m);
  std::size_t k = 0;
  for (std::size_t j = 0; j < plans.size(); ++j) {
    const JointPlan& p = plans[j];
    if (p.owns_slot && (want_world || p.world_for_positions)) {
      float r[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
      for (int i = 0; i < p.rotation_count; ++i) apply_axis(p.axes[i], r, cosines[k + i], sines[k + i]);
      float* w = world + static_cast<std::size_t>(p.world_slot) * 9;
      if (p.parent_slot == kIdentitySlot) {
        std::memcpy(w, r, sizeof r);
      } else {
        mat_mul(world + static_cast<std::size_t>(p.parent_slot) * 9, r, w);
      }
    }
    k += static_cast<std::size_t>(p.rotation_count);
    if (positions) {
      float t[3];
      for (int a = 0; a < 3; ++a) {
        t[a] =
            p.offset_stream[a] == kNoStream ? p.offset[a] : m.stream(static_cast<std::size_t>(p.offset_stream[a]))[f];
      }
      float* pj = out_pos + j * 3;
      if (p.parent == kNoParent) {
        std::memcpy(pj, t, sizeof t);
      } else {
        const float* pp = out_pos + static_cast<std::size_t>(p.parent) * 3;
        const std::int32_t slot = pre ? p.world_slot : p.parent_slot;
        if (p.zero_offset || slot == kIdentitySlot) {
          for (int a = 0; a < 3; ++a) pj[a] = pp[a] + (p.zero_offset ? 0.0f : t[a]);
        } else {
          const float* w = world + static_cast<std::size_t>(slot) * 9;
          for (int a = 0; a < 3; ++a) pj[a] = pp[a] + w[3 * a] * t[0] + w[3 * a + 1] * t[1] + w[3 * a + 2] * t[2];
        }
      }
    }
    if (want_world) {
      const float* w = p.world_slot == kIdentitySlot ? kIdentity : world + static_cast<std::size_t>(p.world_slot) * 9;
      std::memcpy(out_ori + j * 9, w, 9 * sizeof(float));
    }
  }
  if (out_pos != nullptr && m.all_roots()) {
    std::memcpy(out_pos, m.stored_positions(f), plans.size() * 3 * sizeof(float));
  }
}

Status check_frame_args(const CompiledMotion* m, std::size_t frame, std::span<float> pos, std::span<float> ori,
                        std::span<float> ws) {
  if (m == nullptr) return make_error("no motion");
  if (frame >= m->frame_count()) {
    return make_error("frame " + std::to_string(frame) + " out of range (" + std::to_string(m->frame_count()) +
                      " frames)");
  }
  const std::size_t joints = m->joint_count();
  if (pos.size() < joints * 3) return make_error("positions output holds fewer than joints x 3 floats");
  if (!ori.empty() && ori.size() < joints * 9)
    return make_error("orientations output holds fewer than joints x 9 floats");
  if (ws.size() < fk_workspace_size(*m)) return make_error("workspace smaller than fk_workspace_size()");
  return Ok{};
}

}  // namespace

std::size_t fk_workspace_size(const CompiledMotion& motion) {
  return 16 + std::max({range_scratch(motion), frame_scratch(motion), frame_program(motion).workspace_floats});
}

Status FkRangeJob::check() const {
  if (motion == nullptr) return make_error("no motion");
  if (begin > end || end > motion->frame_count()) {
    return make_error("frame range [" + std::to_string(begin) + ", " + std::to_string(end) + ") outside [0, " +
                      std::to_string(motion->frame_count()) + ")");
  }
  const std::size_t frames = end - begin;
  const std::size_t joints = motion->joint_count();
  std::size_t per_component = frames;
  if (layout == Layout::kJointMajor) {
    const std::size_t stride = joint_major_stride == 0 ? frames : joint_major_stride;
    if (stride < frames) return make_error("joint-major stride smaller than the frame range");
    per_component = stride;
  }
  if (out_positions.size() < per_component * joints * 3) {
    return make_error("positions output holds " + std::to_string(out_positions.size()) + " floats, needs " +
                      std::to_string(per_component * joints * 3));
  }
  if (!out_orientations.empty() && out_orientations.size() < per_component * joints * 9) {
    return make_error("orientations output holds " + std::to_string(out_orientations.size()) + " floats, needs " +
                      std::to_string(per_component * joints * 9));
  }
  if (workspace.size() < fk_workspace_size(*motion)) return make_error("workspace smaller than fk_workspace_size()");
  return Ok{};
}

bool FkRangeJob::run() const {
  if (!validate()) return false;
  const CompiledMotion& m = *motion;
  const std::size_t joints = m.joint_count();
  if (begin == end || joints == 0) return true;
  detail::RangeArgs args;
  args.motion = motion;
  args.begin = begin;
  args.end = end;
  args.layout = layout;
  args.stride = joint_major_stride == 0 ? end - begin : joint_major_stride;
  args.positions = !m.all_roots();
  args.workspace = aligned(workspace);
  args.orientations = out_orientations.empty() ? nullptr : out_orientations.data();
  args.positions_out = out_positions.data();

  if (m.all_roots()) {
    // The stored positions are the answer: a copy (frame-major) or a transpose.
    for (std::size_t f = 0; f < end - begin; ++f) {
      const float* src = m.stored_positions(begin + f);
      if (layout == Layout::kFrameMajor) {
        std::memcpy(out_positions.data() + f * joints * 3, src, joints * 3 * sizeof(float));
      } else {
        for (std::size_t k = 0; k < joints * 3; ++k) out_positions[k * args.stride + f] = src[k];
      }
    }
    if (args.orientations == nullptr) return true;
  }
  detail::range_kernel(args);
  return true;
}

Status FkFrameJob::check() const { return check_frame_args(motion, frame, out_positions, out_orientations, workspace); }

bool FkFrameJob::run() const {
  if (!validate()) return false;
  const CompiledMotion& m = *motion;
  float* ws = aligned(workspace);
  const std::size_t padded = padded_rotations(m);
  detail::FrameArgs args;
  args.motion = motion;
  args.frame = frame;
  args.positions = out_positions.data();
  args.orientations = out_orientations.empty() ? nullptr : out_orientations.data();
  args.workspace = ws;
  args.padded_angles = padded;
  if (m.all_roots() && args.orientations == nullptr) {
    std::memcpy(out_positions.data(), m.stored_positions(frame), m.joint_count() * 3 * sizeof(float));
    return true;
  }
  if (detail::frame_kernel(args)) {
    if (m.all_roots()) {
      std::memcpy(out_positions.data(), m.stored_positions(frame), m.joint_count() * 3 * sizeof(float));
    }
    return true;
  }
  float* angles = ws;
  float* sines = angles + padded;
  float* cosines = sines + padded;
  float* world = cosines + padded;
  std::size_t k = 0;
  const bool need_angles = !out_orientations.empty() || !m.all_roots();
  if (need_angles) {
    for (const JointPlan& p : joint_plans(m)) {
      for (int i = 0; i < p.rotation_count; ++i)
        angles[k++] = m.stream(static_cast<std::size_t>(p.rotation_stream[i]))[frame];
    }
    std::fill(angles + k, angles + padded, 0.0f);
    detail::sincos_degrees(angles, k, sines, cosines);
  }
  frame_chain(m, frame, sines, cosines, world, out_positions.data(),
              out_orientations.empty() ? nullptr : out_orientations.data());
  return true;
}

bool scalar_float_frame(const CompiledMotion& motion, std::size_t frame, std::span<float> out_positions,
                        std::span<float> workspace) {
  if (!check_frame_args(&motion, frame, out_positions, {}, workspace).ok()) return false;
  float* ws = aligned(workspace);
  const std::size_t padded = padded_rotations(motion);
  float* sines = ws + padded;
  float* cosines = sines + padded;
  float* world = cosines + padded;
  std::size_t k = 0;
  for (const JointPlan& p : joint_plans(motion)) {
    for (int i = 0; i < p.rotation_count; ++i, ++k) {
      const float x = motion.stream(static_cast<std::size_t>(p.rotation_stream[i]))[frame] * 0.017453292519943295f;
      sines[k] = std::sin(x);
      cosines[k] = std::cos(x);
    }
  }
  frame_chain(motion, frame, sines, cosines, world, out_positions.data(), nullptr);
  return true;
}

const char* simd_target_name() { return detail::target_name(); }
std::size_t simd_lanes() { return detail::lane_count(); }

}  // namespace gmr::fast
