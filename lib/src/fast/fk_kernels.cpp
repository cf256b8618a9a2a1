// SIMD kernels of the fast FK path, compiled once per x86 target (SSE4, AVX2,
// AVX-512, ...) by Highway; HWY_DYNAMIC_DISPATCH picks the best one the CPU
// runs. One vector holds one channel of N consecutive frames, so every joint
// is computed for N frames at once with no shuffles.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "src/fast/fk_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include "src/fast/fk_kernels.h"

HWY_BEFORE_NAMESPACE();
namespace gmr::fast::detail {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

using D = hn::CappedTag<float, kFrameAlignment>;
using V = hn::Vec<D>;

// Polynomial coefficients in degrees: Cephes' single-precision minimax
// polynomials for sin and cos on [-pi/4, pi/4] (error about 1 ulp), with the
// powers of pi/180 folded in so the kernel needs no conversion to radians.
constexpr double kRad = 0.017453292519943295;
constexpr float kS0 = static_cast<float>(kRad);
constexpr float kS1 = static_cast<float>(-1.6666654611e-1 * kRad * kRad * kRad);
constexpr float kS2 = static_cast<float>(8.3321608736e-3 * kRad * kRad * kRad * kRad * kRad);
constexpr float kS3 = static_cast<float>(-1.9515295891e-4 * kRad * kRad * kRad * kRad * kRad * kRad * kRad);
constexpr float kC1 = static_cast<float>(-0.5 * kRad * kRad);
constexpr float kC2 = static_cast<float>(4.166664568298827e-2 * kRad * kRad * kRad * kRad);
constexpr float kC3 = static_cast<float>(-1.388731625493765e-3 * kRad * kRad * kRad * kRad * kRad * kRad);
constexpr float kC4 = static_cast<float>(2.443315711809948e-5 * kRad * kRad * kRad * kRad * kRad * kRad * kRad * kRad);

// sin and cos of x degrees. x = 90 k + r with |r| <= 45 (exact for |x| below
// 2^24 / 90; compiled angles are in [-180, 180]); the quadrant k mod 4 swaps
// and negates the polynomials' values. Absolute error below 1.5e-7.
HWY_INLINE void SinCosDeg(D d, V x, V& out_s, V& out_c) {
  const hn::RebindToSigned<D> di;
  const V k = hn::Round(hn::Mul(x, hn::Set(d, 1.0f / 90.0f)));
  const V r = hn::NegMulAdd(k, hn::Set(d, 90.0f), x);
  const V z = hn::Mul(r, r);
  V ps = hn::MulAdd(hn::Set(d, kS3), z, hn::Set(d, kS2));
  ps = hn::MulAdd(ps, z, hn::Set(d, kS1));
  ps = hn::MulAdd(ps, z, hn::Set(d, kS0));
  ps = hn::Mul(ps, r);
  V pc = hn::MulAdd(hn::Set(d, kC4), z, hn::Set(d, kC3));
  pc = hn::MulAdd(pc, z, hn::Set(d, kC2));
  pc = hn::MulAdd(pc, z, hn::Set(d, kC1));
  pc = hn::MulAdd(pc, z, hn::Set(d, 1.0f));
  const auto q = hn::ConvertTo(di, k);
  const auto one = hn::Set(di, 1);
  const auto two = hn::Set(di, 2);
  const auto swap = hn::RebindMask(d, hn::Eq(hn::And(q, one), one));
  const V s = hn::IfThenElse(swap, pc, ps);
  const V c = hn::IfThenElse(swap, ps, pc);
  // Bit 1 of the quadrant moved to the sign bit: sin < 0 in quadrants 2, 3;
  // cos < 0 in quadrants 1, 2.
  const V sign_s = hn::BitCast(d, hn::ShiftLeft<30>(hn::And(q, two)));
  const V sign_c = hn::BitCast(d, hn::ShiftLeft<30>(hn::And(hn::Add(q, one), two)));
  out_s = hn::Xor(s, sign_s);
  out_c = hn::Xor(c, sign_c);
}

// m <- m * R_axis(c, s): with (u, v) the two other axes in cyclic order,
// column u' = c u + s v, column v' = c v - s u.
template <int kAxis>
HWY_INLINE void ApplyAxis(V* m, V c, V s) {
  constexpr int u = (kAxis + 1) % 3;
  constexpr int v = (kAxis + 2) % 3;
  for (int i = 0; i < 3; ++i) {
    const V mu = m[3 * i + u];
    const V mv = m[3 * i + v];
    m[3 * i + u] = hn::MulAdd(c, mu, hn::Mul(s, mv));
    m[3 * i + v] = hn::NegMulAdd(s, mu, hn::Mul(c, mv));
  }
}

// m <- R_axis(c, s).
template <int kAxis>
HWY_INLINE void InitAxis(D d, V* m, V c, V s) {
  constexpr int u = (kAxis + 1) % 3;
  constexpr int v = (kAxis + 2) % 3;
  const V zero = hn::Zero(d);
  m[3 * kAxis + kAxis] = hn::Set(d, 1.0f);
  m[3 * kAxis + u] = zero;
  m[3 * kAxis + v] = zero;
  m[3 * u + kAxis] = zero;
  m[3 * v + kAxis] = zero;
  m[3 * u + u] = c;
  m[3 * v + v] = c;
  m[3 * u + v] = hn::Neg(s);
  m[3 * v + u] = s;
}

HWY_INLINE V Angle(D d, const CompiledMotion& m, const JointPlan& p, int i, std::size_t f0) {
  return hn::LoadU(d, m.stream(static_cast<std::size_t>(p.rotation_stream[i])) + f0);
}

// W_j = W_p * R_a0 * R_a1 * R_a2 for one joint whose rotation channels have
// the axes A0, A1, A2 (the first kCount of them), stored to `w` (wp null: W_p
// is the identity). Each axis rotation is applied to the running product
// (12 multiply-adds) instead of composing R_j first and multiplying 3x3
// matrices (51). One instantiation per axis order keeps every entry in a register.
template <int kCount, int A0, int A1, int A2>
HWY_NOINLINE void JointWorld(D d, const CompiledMotion& m, const JointPlan& p, std::size_t f0, const float* wp,
                             float* w) {
  const std::size_t n = hn::Lanes(d);
  V r[9];
  V s, c;
  SinCosDeg(d, Angle(d, m, p, 0, f0), s, c);
  if (wp == nullptr) {
    InitAxis<A0>(d, r, c, s);
  } else {
    for (int i = 0; i < 9; ++i) r[i] = hn::Load(d, wp + static_cast<std::size_t>(i) * n);
    ApplyAxis<A0>(r, c, s);
  }
  if constexpr (kCount > 1) {
    SinCosDeg(d, Angle(d, m, p, 1, f0), s, c);
    ApplyAxis<A1>(r, c, s);
  }
  if constexpr (kCount > 2) {
    SinCosDeg(d, Angle(d, m, p, 2, f0), s, c);
    ApplyAxis<A2>(r, c, s);
  }
  for (int i = 0; i < 9; ++i) hn::Store(r[i], d, w + static_cast<std::size_t>(i) * n);
}

using JointWorldFn = void (*)(D, const CompiledMotion&, const JointPlan&, std::size_t, const float*, float*);

// JointWorld for a joint's axis order: index 0..2 (one axis), 3..11 (two),
// 12..38 (three).
JointWorldFn JointWorldFor(const JointPlan& p) {
#define GMR_W3(a, b)                                                             \
  &JointWorld<3, a, b, 0>, &JointWorld<3, a, b, 1>, &JointWorld<3, a, b, 2>
#define GMR_W2(a) &JointWorld<2, a, 0, 0>, &JointWorld<2, a, 1, 0>, &JointWorld<2, a, 2, 0>
  static constexpr JointWorldFn kTable[39] = {
      &JointWorld<1, 0, 0, 0>, &JointWorld<1, 1, 0, 0>, &JointWorld<1, 2, 0, 0>,
      GMR_W2(0), GMR_W2(1), GMR_W2(2),
      GMR_W3(0, 0), GMR_W3(0, 1), GMR_W3(0, 2), GMR_W3(1, 0), GMR_W3(1, 1), GMR_W3(1, 2),
      GMR_W3(2, 0), GMR_W3(2, 1), GMR_W3(2, 2)};
#undef GMR_W3
#undef GMR_W2
  const int a0 = p.axes[0], a1 = p.axes[1], a2 = p.axes[2];
  switch (p.rotation_count) {
    case 1: return kTable[a0];
    case 2: return kTable[3 + a0 * 3 + a1];
    default: return kTable[12 + a0 * 9 + a1 * 3 + a2];
  }
}

void RangeKernel(const RangeArgs& a) {
  const D d;
  const std::size_t n = hn::Lanes(d);
  const CompiledMotion& m = *a.motion;
  const auto plans = m.joints();
  const std::size_t joints = plans.size();
  float* const world = a.workspace;                               // slot_count * 9 * n
  float* const pos = world + m.slot_count() * 9 * kFrameAlignment;  // joints * 3 * n
  const bool pre = m.convention() == Convention::kPreRotation;
  const bool want_world = a.orientations != nullptr;

  for (std::size_t f0 = a.begin; f0 < a.end; f0 += n) {
    const std::size_t count = std::min(n, a.end - f0);
    const bool direct = a.positions && a.layout == Layout::kJointMajor && count == n;
    for (std::size_t j = 0; j < joints; ++j) {
      const JointPlan& p = plans[j];
      if (p.owns_slot && (want_world || p.world_for_positions)) {
        const float* wp = p.parent_slot == kIdentitySlot ? nullptr : world + static_cast<std::size_t>(p.parent_slot) * 9 * n;
        JointWorldFor(p)(d, m, p, f0, wp, world + static_cast<std::size_t>(p.world_slot) * 9 * n);
      }
      if (!a.positions) continue;
      V t[3];
      for (int ax = 0; ax < 3; ++ax) {
        t[ax] = p.offset_stream[ax] == kNoStream
                    ? hn::Set(d, p.offset[ax])
                    : hn::LoadU(d, m.stream(static_cast<std::size_t>(p.offset_stream[ax])) + f0);
      }
      // Full blocks of joint-major output are written in place (children read
      // their parent's position back from there); other blocks go through
      // the scratch and write_block().
      float* pj = direct ? a.positions_out + j * 3 * a.stride + (f0 - a.begin) : pos + j * 3 * n;
      const std::size_t step = direct ? a.stride : n;
      if (p.parent == kNoParent) {
        for (int ax = 0; ax < 3; ++ax) hn::StoreU(t[ax], d, pj + ax * step);
        continue;
      }
      const float* pp = direct ? a.positions_out + static_cast<std::size_t>(p.parent) * 3 * a.stride + (f0 - a.begin)
                               : pos + static_cast<std::size_t>(p.parent) * 3 * n;
      const std::int32_t slot = pre ? p.world_slot : p.parent_slot;
      if (p.zero_offset) {
        for (int ax = 0; ax < 3; ++ax) hn::StoreU(hn::LoadU(d, pp + ax * step), d, pj + ax * step);
      } else if (slot == kIdentitySlot) {
        for (int ax = 0; ax < 3; ++ax) hn::StoreU(hn::Add(hn::LoadU(d, pp + ax * step), t[ax]), d, pj + ax * step);
      } else {
        const float* w = world + static_cast<std::size_t>(slot) * 9 * n;
        for (int row = 0; row < 3; ++row) {
          V acc = hn::LoadU(d, pp + row * step);
          acc = hn::MulAdd(hn::Load(d, w + (3 * row + 0) * n), t[0], acc);
          acc = hn::MulAdd(hn::Load(d, w + (3 * row + 1) * n), t[1], acc);
          acc = hn::MulAdd(hn::Load(d, w + (3 * row + 2) * n), t[2], acc);
          hn::StoreU(acc, d, pj + row * step);
        }
      }
    }
    write_block(a, f0, count, n, world, pos, direct);
  }
}

// sin and cos of `count` angles in degrees (buffers padded to a multiple of
// kFrameAlignment).
void SinCosArray(const float* angles, std::size_t count, float* out_s, float* out_c) {
  const D d;
  const std::size_t n = hn::Lanes(d);
  for (std::size_t i = 0; i < count; i += n) {
    V s, c;
    SinCosDeg(d, hn::LoadU(d, angles + i), s, c);
    hn::StoreU(s, d, out_s + i);
    hn::StoreU(c, d, out_c + i);
  }
}

#if HWY_TARGET != HWY_SCALAR
// ---- One frame (FkFrameJob). Lanes across frames would waste all but one,
// so here a 4-float vector holds one column of a 3x3 matrix (or a position):
// W_j = W_p R_j is 9 broadcasts and 9 multiply-adds, a position 3.
using D4 = hn::Full128<float>;
using V4 = hn::Vec<D4>;

// m <- m * R_axis(c, s) on the columns of m: col_u' = c col_u + s col_v,
// col_v' = c col_v - s col_u.
template <int kAxis>
HWY_INLINE void ApplyAxisCols(V4* col, V4 c, V4 s) {
  constexpr int u = (kAxis + 1) % 3;
  constexpr int v = (kAxis + 2) % 3;
  const V4 cu = col[u];
  const V4 cv = col[v];
  col[u] = hn::MulAdd(c, cu, hn::Mul(s, cv));
  col[v] = hn::NegMulAdd(s, cu, hn::Mul(c, cv));
}

alignas(16) constexpr float kIdentityColumns[12] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0};

// W_j = W_p * R_a0 * R_a1 * R_a2 as 3 columns of 4 floats (wp null: identity).
template <int kCount, int A0, int A1, int A2>
HWY_NOINLINE void FrameJointWorld(const float* sines, const float* cosines, const float* wp, float* w) {
  const D4 d;
  if (wp == nullptr) wp = kIdentityColumns;
  V4 col[3] = {hn::Load(d, wp), hn::Load(d, wp + 4), hn::Load(d, wp + 8)};
  ApplyAxisCols<A0>(col, hn::Set(d, cosines[0]), hn::Set(d, sines[0]));
  if constexpr (kCount > 1) ApplyAxisCols<A1>(col, hn::Set(d, cosines[1]), hn::Set(d, sines[1]));
  if constexpr (kCount > 2) ApplyAxisCols<A2>(col, hn::Set(d, cosines[2]), hn::Set(d, sines[2]));
  for (int k = 0; k < 3; ++k) hn::Store(col[k], d, w + 4 * k);
}

using FrameJointFn = void (*)(const float*, const float*, const float*, float*);

FrameJointFn FrameJointFor(const JointPlan& p) {
#define GMR_F3(a, b) &FrameJointWorld<3, a, b, 0>, &FrameJointWorld<3, a, b, 1>, &FrameJointWorld<3, a, b, 2>
#define GMR_F2(a) &FrameJointWorld<2, a, 0, 0>, &FrameJointWorld<2, a, 1, 0>, &FrameJointWorld<2, a, 2, 0>
  static constexpr FrameJointFn kTable[39] = {
      &FrameJointWorld<1, 0, 0, 0>, &FrameJointWorld<1, 1, 0, 0>, &FrameJointWorld<1, 2, 0, 0>,
      GMR_F2(0), GMR_F2(1), GMR_F2(2),
      GMR_F3(0, 0), GMR_F3(0, 1), GMR_F3(0, 2), GMR_F3(1, 0), GMR_F3(1, 1), GMR_F3(1, 2),
      GMR_F3(2, 0), GMR_F3(2, 1), GMR_F3(2, 2)};
#undef GMR_F3
#undef GMR_F2
  const int a0 = p.axes[0], a1 = p.axes[1], a2 = p.axes[2];
  switch (p.rotation_count) {
    case 1: return kTable[a0];
    case 2: return kTable[3 + a0 * 3 + a1];
    default: return kTable[12 + a0 * 9 + a1 * 3 + a2];
  }
}

bool FrameKernel(const FrameArgs& a) {
  const CompiledMotion& m = *a.motion;
  const auto plans = m.joints();
  const std::size_t f = a.frame;
  const bool pre = m.convention() == Convention::kPreRotation;
  const bool want_world = a.orientations != nullptr;
  const bool positions = !m.all_roots();
  // A frame's angles: one gather per vector from the streams (offsets are
  // stream * frame_stride, padded with stream 0).
  const auto offsets = m.rotation_gather_offsets();
  float* sines = a.workspace + a.padded_angles;
  float* cosines = sines + a.padded_angles;
  {
    const D d;
    const hn::RebindToSigned<D> di;
    const float* base = m.stream(0) + f;
    for (std::size_t i = 0; i < offsets.size(); i += hn::Lanes(d)) {
      V s, c;
      SinCosDeg(d, hn::GatherIndex(d, base, hn::LoadU(di, offsets.data() + i)), s, c);
      hn::Store(s, d, sines + i);
      hn::Store(c, d, cosines + i);
    }
  }
  float* world = cosines + a.padded_angles;  // slot_count * 12
  const D4 d;
  std::size_t k = 0;
  for (std::size_t j = 0; j < plans.size(); ++j) {
    const JointPlan& p = plans[j];
    if (p.owns_slot && (want_world || p.world_for_positions)) {
      FrameJointFor(p)(sines + k, cosines + k,
                       p.parent_slot == kIdentitySlot ? nullptr : world + static_cast<std::size_t>(p.parent_slot) * 12,
                       world + static_cast<std::size_t>(p.world_slot) * 12);
    }
    k += static_cast<std::size_t>(p.rotation_count);
    if (!positions) continue;
    float t[3];
    for (int ax = 0; ax < 3; ++ax) {
      t[ax] = p.offset_stream[ax] == kNoStream ? p.offset[ax] : m.stream(static_cast<std::size_t>(p.offset_stream[ax]))[f];
    }
    // Positions go straight to the output with 4-float stores at 3 j: the 4th
    // float lands on joint j + 1's x, which is written next (joints are in
    // order); the last joint is stored in 3 floats. Lane 3 only ever holds
    // such leftovers and never mixes into lanes 0..2.
    float* pj = a.positions + 3 * j;
    const bool last = j + 1 == plans.size();
    if (p.parent == kNoParent) {
      pj[0] = t[0];
      pj[1] = t[1];
      pj[2] = t[2];
      continue;
    }
    V4 acc = hn::LoadU(d, a.positions + 3 * static_cast<std::size_t>(p.parent));
    const std::int32_t slot = pre ? p.world_slot : p.parent_slot;
    if (!p.zero_offset) {
      if (slot == kIdentitySlot) {
        alignas(16) const float t4[4] = {t[0], t[1], t[2], 0.0f};
        acc = hn::Add(acc, hn::Load(d, t4));
      } else {
        const float* w = world + static_cast<std::size_t>(slot) * 12;
        acc = hn::MulAdd(hn::Set(d, t[0]), hn::Load(d, w), acc);
        acc = hn::MulAdd(hn::Set(d, t[1]), hn::Load(d, w + 4), acc);
        acc = hn::MulAdd(hn::Set(d, t[2]), hn::Load(d, w + 8), acc);
      }
    }
    if (!last) {
      hn::StoreU(acc, d, pj);
    } else {
      alignas(16) float tmp[4];
      hn::Store(acc, d, tmp);
      pj[0] = tmp[0];
      pj[1] = tmp[1];
      pj[2] = tmp[2];
    }
  }
  if (want_world) {
    for (std::size_t j = 0; j < plans.size(); ++j) {
      const std::int32_t slot = plans[j].world_slot;
      float* o = a.orientations + 9 * j;
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) {
          o[3 * r + c] = slot == kIdentitySlot ? (r == c ? 1.0f : 0.0f) : world[static_cast<std::size_t>(slot) * 12 + 4 * static_cast<std::size_t>(c) + static_cast<std::size_t>(r)];
        }
      }
    }
  }
  return true;
}
#else
bool FrameKernel(const FrameArgs&) { return false; }  // the caller's scalar chain does it
#endif

const char* TargetName() { return hwy::TargetName(HWY_TARGET); }
std::size_t LaneCount() { return hn::Lanes(D()); }

}  // namespace HWY_NAMESPACE
}  // namespace gmr::fast::detail
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace gmr::fast::detail {

HWY_EXPORT(RangeKernel);
HWY_EXPORT(SinCosArray);
HWY_EXPORT(FrameKernel);
HWY_EXPORT(TargetName);
HWY_EXPORT(LaneCount);

void range_kernel(const RangeArgs& args) { HWY_DYNAMIC_DISPATCH(RangeKernel)(args); }
void sincos_degrees(const float* angles, std::size_t count, float* out_s, float* out_c) {
  HWY_DYNAMIC_DISPATCH(SinCosArray)(angles, count, out_s, out_c);
}
bool frame_kernel(const FrameArgs& args) { return HWY_DYNAMIC_DISPATCH(FrameKernel)(args); }
const char* target_name() { return HWY_DYNAMIC_DISPATCH(TargetName)(); }
std::size_t lane_count() { return HWY_DYNAMIC_DISPATCH(LaneCount)(); }

}  // namespace gmr::fast::detail
#endif
