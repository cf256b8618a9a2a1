// SIMD kernels of the fast FK path, compiled once per x86 target (SSE4, AVX2,
// AVX-512, ...) by Highway; HWY_DYNAMIC_DISPATCH picks the best one the CPU
// runs. One vector holds one channel of N consecutive frames, so every joint
// is computed for N frames at once with no shuffles.
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "fast/fk_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include <algorithm>
#include <cstring>

#include "fast/fk_kernels.h"

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
// 2^22 / 90; compiled angles are in [-180, 180]); the quadrant k mod 4 swaps
// and negates the polynomials' values. Absolute error below 1.5e-7.
HWY_INLINE void SinCosDeg(D d, V x, V& out_s, V& out_c) {
  const hn::RebindToSigned<D> di;
  // k = round(x / 90) by the 1.5 * 2^23 trick: adding it leaves k in the low
  // bits of the sum's mantissa (two's complement, so k < 0 works), which
  // gives the quadrant without a rounding or conversion instruction.
  const V magic = hn::Set(d, 12582912.0f);
  const V t = hn::MulAdd(x, hn::Set(d, 1.0f / 90.0f), magic);
  const V k = hn::Sub(t, magic);
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
  const auto q = hn::BitCast(di, t);
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
#define GMR_W3(a, b) &JointWorld<3, a, b, 0>, &JointWorld<3, a, b, 1>, &JointWorld<3, a, b, 2>
#define GMR_W2(a) &JointWorld<2, a, 0, 0>, &JointWorld<2, a, 1, 0>, &JointWorld<2, a, 2, 0>
  static constexpr JointWorldFn kTable[39] = {&JointWorld<1, 0, 0, 0>,
                                              &JointWorld<1, 1, 0, 0>,
                                              &JointWorld<1, 2, 0, 0>,
                                              GMR_W2(0),
                                              GMR_W2(1),
                                              GMR_W2(2),
                                              GMR_W3(0, 0),
                                              GMR_W3(0, 1),
                                              GMR_W3(0, 2),
                                              GMR_W3(1, 0),
                                              GMR_W3(1, 1),
                                              GMR_W3(1, 2),
                                              GMR_W3(2, 0),
                                              GMR_W3(2, 1),
                                              GMR_W3(2, 2)};
#undef GMR_W3
#undef GMR_W2
  const int a0 = p.axes[0], a1 = p.axes[1], a2 = p.axes[2];
  switch (p.rotation_count) {
    case 1:
      return kTable[a0];
    case 2:
      return kTable[3 + a0 * 3 + a1];
    default:
      return kTable[12 + a0 * 9 + a1 * 3 + a2];
  }
}

// Frame-major output of one block: src[k * lanes + l] (component k of frame
// l) to dst[l * comps + k] for l < count, in 4 x 4 tiles of 128-bit
// vectors (a scalar copy of the same is ~2x slower); the edges are scalar.
HWY_INLINE void TransposeToFrameMajor(const float* src, std::size_t lanes, std::size_t comps, std::size_t count,
                                      float* dst) {
  std::size_t l = 0;
#if HWY_TARGET != HWY_SCALAR
  const hn::Full128<float> d4;
  for (; l + 4 <= count; l += 4) {
    std::size_t k = 0;
    for (; k + 4 <= comps; k += 4) {
      const auto r0 = hn::LoadU(d4, src + k * lanes + l);
      const auto r1 = hn::LoadU(d4, src + (k + 1) * lanes + l);
      const auto r2 = hn::LoadU(d4, src + (k + 2) * lanes + l);
      const auto r3 = hn::LoadU(d4, src + (k + 3) * lanes + l);
      const auto t0 = hn::InterleaveLower(d4, r0, r1);  // r00 r10 r01 r11
      const auto t1 = hn::InterleaveLower(d4, r2, r3);  // r20 r30 r21 r31
      const auto t2 = hn::InterleaveUpper(d4, r0, r1);  // r02 r12 r03 r13
      const auto t3 = hn::InterleaveUpper(d4, r2, r3);  // r22 r32 r23 r33
      hn::StoreU(hn::ConcatLowerLower(d4, t1, t0), d4, dst + l * comps + k);
      hn::StoreU(hn::ConcatUpperUpper(d4, t1, t0), d4, dst + (l + 1) * comps + k);
      hn::StoreU(hn::ConcatLowerLower(d4, t3, t2), d4, dst + (l + 2) * comps + k);
      hn::StoreU(hn::ConcatUpperUpper(d4, t3, t2), d4, dst + (l + 3) * comps + k);
    }
    for (; k < comps; ++k) {
      for (std::size_t i = 0; i < 4; ++i) dst[(l + i) * comps + k] = src[k * lanes + l + i];
    }
  }
#endif
  for (; l < count; ++l) {
    for (std::size_t k = 0; k < comps; ++k) dst[l * comps + k] = src[k * lanes + l];
  }
}

void RangeKernel(const RangeArgs& a) {
  const D d;
  const std::size_t n = hn::Lanes(d);
  const CompiledMotion& m = *a.motion;
  const auto plans = joint_plans(m);
  const std::size_t joints = plans.size();
  float* const world = a.workspace;                                 // slot_count * 9 * n
  float* const pos = world + m.slot_count() * 9 * kFrameAlignment;  // joints * 3 * n
  const bool pre = m.convention() == Convention::kPreRotation;
  const bool want_world = a.orientations != nullptr;

  for (std::size_t f0 = a.begin; f0 < a.end; f0 += n) {
    const std::size_t count = std::min(n, a.end - f0);
    const bool direct = a.positions && a.layout == Layout::kJointMajor && count == n;
    for (std::size_t j = 0; j < joints; ++j) {
      const JointPlan& p = plans[j];
      if (p.owns_slot && (want_world || p.world_for_positions)) {
        const float* wp =
            p.parent_slot == kIdentitySlot ? nullptr : world + static_cast<std::size_t>(p.parent_slot) * 9 * n;
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
    bool written = direct;
    if (a.positions && !direct && a.layout == Layout::kFrameMajor) {
      TransposeToFrameMajor(pos, n, joints * 3, count, a.positions_out + (f0 - a.begin) * joints * 3);
      written = true;
    }
    write_block(a, f0, count, n, world, pos, written);
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

// Local rotations R = R_A0 R_A1 R_A2 of one group of joints (the first kCount
// axes), SIMD across joints: local index i's angle r at sines/cosines
// [r * stride + i], entry e of R at local[e * stride + i].
template <int kCount, int A0, int A1, int A2>
HWY_NOINLINE void LocalGroup(const float* sines, const float* cosines, float* local, std::size_t first,
                             std::size_t size, std::size_t stride) {
  const D d;
  const std::size_t n = hn::Lanes(d);
  for (std::size_t i = first; i < first + size; i += n) {
    V r[9];
    InitAxis<A0>(d, r, hn::Load(d, cosines + i), hn::Load(d, sines + i));
    if constexpr (kCount > 1) ApplyAxis<A1>(r, hn::Load(d, cosines + stride + i), hn::Load(d, sines + stride + i));
    if constexpr (kCount > 2) {
      ApplyAxis<A2>(r, hn::Load(d, cosines + 2 * stride + i), hn::Load(d, sines + 2 * stride + i));
    }
    for (std::size_t e = 0; e < 9; ++e) hn::Store(r[e], d, local + e * stride + i);
  }
}

using LocalGroupFn = void (*)(const float*, const float*, float*, std::size_t, std::size_t, std::size_t);

// LocalGroup for an axis order: index 0..2 (one axis), 3..11 (two), 12..38 (three).
LocalGroupFn LocalGroupFor(const FrameProgram::Group& g) {
#define GMR_L3(a, b) &LocalGroup<3, a, b, 0>, &LocalGroup<3, a, b, 1>, &LocalGroup<3, a, b, 2>
#define GMR_L2(a) &LocalGroup<2, a, 0, 0>, &LocalGroup<2, a, 1, 0>, &LocalGroup<2, a, 2, 0>
  static constexpr LocalGroupFn kTable[39] = {&LocalGroup<1, 0, 0, 0>,
                                              &LocalGroup<1, 1, 0, 0>,
                                              &LocalGroup<1, 2, 0, 0>,
                                              GMR_L2(0),
                                              GMR_L2(1),
                                              GMR_L2(2),
                                              GMR_L3(0, 0),
                                              GMR_L3(0, 1),
                                              GMR_L3(0, 2),
                                              GMR_L3(1, 0),
                                              GMR_L3(1, 1),
                                              GMR_L3(1, 2),
                                              GMR_L3(2, 0),
                                              GMR_L3(2, 1),
                                              GMR_L3(2, 2)};
#undef GMR_L3
#undef GMR_L2
  const int a0 = g.axes[0], a1 = g.axes[1], a2 = g.axes[2];
  switch (g.count) {
    case 1:
      return kTable[a0];
    case 2:
      return kTable[3 + a0 * 3 + a1];
    default:
      return kTable[12 + a0 * 9 + a1 * 3 + a2];
  }
}

// P_j = P_p + W t_j for one position-only op (W read back from the world buffer).
HWY_INLINE void RunPosOp(const FrameProgram::PosOp& op, const float* world, const float* offsets, float* pos) {
  const D4 d;
  const float* w = world + op.world;
  const float* t = offsets + op.t;
  V4 wt = hn::Mul(hn::Load(d, w), hn::Set(d, t[0]));
  wt = hn::MulAdd(hn::Load(d, w + 4), hn::Set(d, t[1]), wt);
  wt = hn::MulAdd(hn::Load(d, w + 8), hn::Set(d, t[2]), wt);
  hn::Store(hn::Add(hn::Load(d, pos + op.parent), wt), d, pos + op.pos);
}

// The per-joint steps (see FrameProgram): W_out = W_from R_j, then
// P_j = P_p + W t_j with W = W_out (pre-rotation) or W_from (post-rotation),
// both still in registers, then the step's position-only ops. Column c of
// W_from R_j = sum over k of column k of W_from times R_j[k][c].
template <bool kPre, bool kPositions>
HWY_INLINE void RunSteps(const FrameProgram& prog, std::size_t nl, const float* local, float* world,
                         const float* offsets, float* pos) {
  const D4 d;
  const FrameProgram::Step* steps = prog.steps.data();
  const FrameProgram::PosOp* ops = prog.ops.data();
  const std::size_t count = prog.steps.size();
  if constexpr (kPositions) {
    for (std::uint32_t k = 0; k < prog.prologue; ++k) RunPosOp(ops[k], world, offsets, pos);
  }
  for (std::size_t j = 0; j < count; ++j) {
    const FrameProgram::Step& st = steps[j];
    const float* wp = world + st.from;
    const float* r = local + st.local;
    const V4 c0 = hn::Load(d, wp);
    const V4 c1 = hn::Load(d, wp + 4);
    const V4 c2 = hn::Load(d, wp + 8);
    V4 w[3];
    for (std::size_t c = 0; c < 3; ++c) {
      V4 col = hn::Mul(c0, hn::Set(d, r[c * nl]));
      col = hn::MulAdd(c1, hn::Set(d, r[(3 + c) * nl]), col);
      w[c] = hn::MulAdd(c2, hn::Set(d, r[(6 + c) * nl]), col);
      hn::Store(w[c], d, world + st.out + 4 * c);
    }
    if constexpr (kPositions) {
      // W t_j first, then one add: the chain from parent to child is one add.
      const float* t = offsets + st.t;
      V4 wt = hn::Mul(kPre ? w[0] : c0, hn::Set(d, t[0]));
      wt = hn::MulAdd(kPre ? w[1] : c1, hn::Set(d, t[1]), wt);
      wt = hn::MulAdd(kPre ? w[2] : c2, hn::Set(d, t[2]), wt);
      hn::Store(hn::Add(hn::Load(d, pos + st.parent), wt), d, pos + st.pos);
      for (std::uint32_t k = st.ops_begin; k < st.ops_end; ++k) RunPosOp(ops[k], world, offsets, pos);
    }
  }
}

// One frame by the motion's FrameProgram (see compiled_motion.h): the
// frame's angles and one SIMD sincos pass, local rotations SIMD across joints,
// then one flat loop over the rotating joints (each with its trailing
// position-only ops) and one over the end sites.
bool FrameKernel(const FrameArgs& a) {
  const CompiledMotion& m = *a.motion;
  const FrameProgram& prog = frame_program(m);
  const std::size_t f = a.frame;
  const std::size_t nl = prog.local_count;
  const std::size_t joints = m.joint_count();
  const bool want_world = a.orientations != nullptr;
  const bool positions = !m.all_roots();
  float* const sines = a.workspace;
  float* const cosines = sines + 3 * nl;
  float* const local = cosines + 3 * nl;
  float* const world = local + 9 * nl;                       // (slot_count + 1) * 12: identity, slots
  float* const offsets = world + 12 * (m.slot_count() + 1);  // joints * 4
  float* const pos = offsets + 4 * joints;                   // (joints + 2) * 4: zero, joints, scratch
  {
    // The frame's angles, role-major, are stored frame-major at compile time
    // (FrameProgram::angles): one SIMD sincos pass reads them contiguously.
    const D d;
    const float* angles = nl == 0 ? nullptr : prog.angles.get() + f * 3 * nl;
    for (std::size_t i = 0; i < 3 * nl; i += hn::Lanes(d)) {
      V s, c;
      SinCosDeg(d, hn::Load(d, angles + i), s, c);
      hn::Store(s, d, sines + i);
      hn::Store(c, d, cosines + i);
    }
  }
  for (const FrameProgram::Group& g : prog.groups) LocalGroupFor(g)(sines, cosines, local, g.first, g.size, nl);

  const D4 d;
  for (int k = 0; k < 3; ++k) hn::Store(hn::Load(d, kIdentityColumns + 4 * k), d, world + 4 * k);
  if (positions) {
    std::memcpy(offsets, prog.offsets.data(), joints * 4 * sizeof(float));
    for (const FrameProgram::Patch& p : prog.patches) {
      offsets[p.dst] = m.stream(static_cast<std::size_t>(p.stream))[f];
    }
    hn::Store(hn::Zero(d), d, pos);
    for (const std::int32_t r : prog.roots) {
      hn::Store(hn::Load(d, offsets + 4 * r), d, pos + 4 * (r + 1));
    }
  }
  if (!positions) {
    RunSteps<false, false>(prog, nl, local, world, offsets, pos);
  } else if (m.convention() == Convention::kPreRotation) {
    RunSteps<true, true>(prog, nl, local, world, offsets, pos);
  } else {
    RunSteps<false, true>(prog, nl, local, world, offsets, pos);
  }
  if (positions) {
    for (const FrameProgram::PosOp& leaf : prog.leaves) RunPosOp(leaf, world, offsets, pos);
  }
  if (positions && joints > 0) {
    // Pack 4-float entries into 3-float ones: each 4-float store's last float
    // is overwritten by the next joint's store; the last joint takes 3 floats.
    float* out = a.positions;
    for (std::size_t j = 0; j + 1 < joints; ++j) hn::StoreU(hn::Load(d, pos + 4 * (j + 1)), d, out + 3 * j);
    const float* last = pos + 4 * joints;
    out[3 * (joints - 1)] = last[0];
    out[3 * (joints - 1) + 1] = last[1];
    out[3 * (joints - 1) + 2] = last[2];
  }
  if (want_world) {
    const auto plans = joint_plans(m);
    for (std::size_t j = 0; j < joints; ++j) {
      const float* w = world + static_cast<std::size_t>(plans[j].world_slot + 1) * 12;
      float* o = a.orientations + 9 * j;
      for (std::size_t r = 0; r < 3; ++r) {
        for (std::size_t c = 0; c < 3; ++c) o[3 * r + c] = w[4 * c + r];
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
