#include "gmr/fast/compiled_motion.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <new>
#include <string>

#include "fast/frame_program.h"

namespace gmr::fast {

CompiledMotion::CompiledMotion() : plan_(std::make_unique<detail::CompiledPlan>()) {}
CompiledMotion::~CompiledMotion() = default;
CompiledMotion::CompiledMotion(CompiledMotion&&) noexcept = default;
CompiledMotion& CompiledMotion::operator=(CompiledMotion&&) noexcept = default;

std::size_t CompiledMotion::frame_program_bytes_per_frame() const {
  return 3 * plan_->program.local_count * sizeof(float);
}

void CompiledMotion::AlignedFree::operator()(float* p) const { ::operator delete[](p, std::align_val_t{64}); }
void FrameProgram::AngleFree::operator()(float* p) const { ::operator delete[](p, std::align_val_t{64}); }

namespace {

// Rounds up to a multiple of kFrameAlignment and adds one block, so a vector
// load starting at any valid frame stays inside the stream.
std::size_t padded_frames(std::size_t frames) {
  return (frames + kFrameAlignment - 1) / kFrameAlignment * kFrameAlignment + kFrameAlignment;
}

// True when the joint's rotation channels (indices `channel` within its
// channels) are multiples of 360 degrees in every frame.
bool all_identity(const Motion& motion, int joint, const int* channel, int count) {
  if (motion.frame_count == 0) return true;  // and values.data() may be null: no pointer arithmetic on it
  const std::size_t stride = motion.stride();
  const std::size_t first = static_cast<std::size_t>(motion.skeleton.channel_offset(joint));
  for (int r = 0; r < count; ++r) {
    const double* v = motion.values.data() + first + static_cast<std::size_t>(channel[r]);
    for (std::size_t f = 0; f < motion.frame_count; ++f) {
      if (std::remainder(v[f * stride], 360.0) != 0.0) return false;
    }
  }
  return true;
}

}  // namespace

Result<CompiledMotion> CompiledMotion::compile(const Motion& motion) {
  if (Status s = motion.validate(); !s.ok()) return s.error();
  const Skeleton& sk = motion.skeleton;
  const std::size_t joints = sk.size();

  CompiledMotion out;
  out.convention_ = motion.convention;
  out.frame_count_ = motion.frame_count;
  out.frame_stride_ = padded_frames(motion.frame_count);
  out.all_roots_ = joints > 0 && sk.roots().size() == joints;
  out.plan_->joints.resize(joints);
  out.joint_count_ = joints;

  // Streams: every rotation channel, and every position channel unless all
  // joints are roots (then positions come from stored_positions_).
  std::int32_t streams = 0;
  std::int32_t slots = 0;
  for (std::size_t j = 0; j < joints; ++j) {
    const Joint& joint = sk.joint(static_cast<int>(j));
    JointPlan& p = out.plan_->joints[j];
    p.parent = joint.parent;
    p.parent_slot = joint.parent == kNoParent ? kIdentitySlot
                                              : out.plan_->joints[static_cast<std::size_t>(joint.parent)].world_slot;
    for (int a = 0; a < 3; ++a) p.offset[a] = static_cast<float>(joint.offset[a]);
    int rotation_channel[3] = {0, 0, 0};  // index of each rotation channel in joint.channels
    for (std::size_t i = 0; i < joint.channels.size(); ++i) {
      if (!is_rotation(joint.channels[i])) continue;
      rotation_channel[p.rotation_count] = static_cast<int>(i);
      p.axes[p.rotation_count++] = static_cast<std::uint8_t>(axis_of(joint.channels[i]));
    }
    // Rotation channels that are a multiple of 360 degrees in every frame (CMU's
    // LHipJoint and RHipJoint: always 0) are the identity: no rotation to
    // compute, exactly what computing it would give (sin 0 = 0, cos 0 = 1).
    if (p.rotation_count > 0 && all_identity(motion, static_cast<int>(j), rotation_channel, p.rotation_count)) {
      p.rotation_count = 0;
    }
    // Siblings that rotate identically share one world rotation: converting
    // BVH to GMR gives each child of a joint a copy of its rotation channels,
    // and computing them once keeps the one-root GMR as cheap as the BVH.
    int twin = -1;
    for (std::size_t i = 0; i < j && p.rotation_count > 0 && twin < 0; ++i) {
      const JointPlan& q = out.plan_->joints[i];
      if (!q.owns_slot || q.parent_slot != p.parent_slot || q.rotation_count != p.rotation_count ||
          !std::equal(q.axes, q.axes + 3, p.axes)) {
        continue;
      }
      const Joint& other = sk.joint(static_cast<int>(i));
      std::size_t k = 0;
      int other_channel[3] = {0, 0, 0};
      for (std::size_t c = 0; c < other.channels.size(); ++c) {
        if (is_rotation(other.channels[c])) other_channel[k++] = static_cast<int>(c);
      }
      bool same = true;
      const std::size_t stride = motion.stride();
      const std::size_t a0 = static_cast<std::size_t>(sk.channel_offset(static_cast<int>(j)));
      const std::size_t b0 = static_cast<std::size_t>(sk.channel_offset(static_cast<int>(i)));
      // (No frames: twins vacuously, and no pointer into the possibly null values.)
      for (int r = 0; r < p.rotation_count && same && motion.frame_count > 0; ++r) {
        const double* a = motion.values.data() + a0 + static_cast<std::size_t>(rotation_channel[r]);
        const double* b = motion.values.data() + b0 + static_cast<std::size_t>(other_channel[r]);
        for (std::size_t f = 0; f < motion.frame_count && same; ++f) same = a[f * stride] == b[f * stride];
      }
      if (same) twin = static_cast<int>(i);
    }
    if (twin >= 0) {
      // No rotation of its own to compute: it uses its twin's world rotation.
      p.rotation_count = 0;
      p.world_slot = out.plan_->joints[static_cast<std::size_t>(twin)].world_slot;
    } else {
      for (int r = 0; r < p.rotation_count; ++r) p.rotation_stream[r] = streams++;
    }
    for (ChannelType c : joint.channels) {
      if (is_position(c) && !out.all_roots_) p.offset_stream[static_cast<int>(axis_of(c))] = streams++;
    }
    bool has_pos = false;
    for (ChannelType c : joint.channels) has_pos = has_pos || is_position(c);
    p.zero_offset = !has_pos && joint.offset.isZero(0.0);
    p.owns_slot = p.rotation_count > 0;
    if (twin < 0) p.world_slot = p.owns_slot ? slots++ : p.parent_slot;
    if (streams < 0 || slots < 0) return make_error("motion has too many channels to compile");
  }

  // Which world rotations positions need (orientation requests compute all):
  // post-rotation reads W_p, pre-rotation W_j; computing a slot needs its
  // parent's slot. Owners come before their users, so one backward pass
  // propagates the marks.
  std::vector<char> needed(static_cast<std::size_t>(slots), 0);
  const bool pre = motion.convention == Convention::kPreRotation;
  for (const JointPlan& p : out.plan_->joints) {
    if (p.parent == kNoParent || p.zero_offset) continue;
    const std::int32_t s = pre ? p.world_slot : p.parent_slot;
    if (s != kIdentitySlot) needed[static_cast<std::size_t>(s)] = 1;
  }
  for (std::size_t j = joints; j-- > 0;) {
    JointPlan& p = out.plan_->joints[j];
    if (!p.owns_slot || !needed[static_cast<std::size_t>(p.world_slot)]) continue;
    p.world_for_positions = true;
    if (p.parent_slot != kIdentitySlot) needed[static_cast<std::size_t>(p.parent_slot)] = 1;
  }

  out.stream_count_ = static_cast<std::size_t>(streams);
  out.slot_count_ = static_cast<std::size_t>(slots);
  const std::size_t total = out.stream_count_ * out.frame_stride_;
  // 32-bit stream offsets keep gathers possible; 2^31 floats is 8 GiB per motion.
  if (out.frame_stride_ > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()) ||
      (out.stream_count_ != 0 && total / out.stream_count_ != out.frame_stride_) ||
      total > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())) {
    return make_error("motion too large to compile (" + std::to_string(motion.frame_count) + " frames x " +
                      std::to_string(out.stream_count_) + " channels)");
  }
  if (total > 0) {
    out.streams_.reset(static_cast<float*>(::operator new[](total * sizeof(float), std::align_val_t{64})));
    std::memset(out.streams_.get(), 0, total * sizeof(float));
  }

  const std::size_t stride = motion.stride();
  for (std::size_t j = 0; j < joints; ++j) {
    const Joint& joint = sk.joint(static_cast<int>(j));
    const JointPlan& p = out.plan_->joints[j];
    const std::size_t first = static_cast<std::size_t>(sk.channel_offset(static_cast<int>(j)));
    int r = 0;
    for (std::size_t i = 0; i < joint.channels.size(); ++i) {
      const ChannelType c = joint.channels[i];
      std::int32_t s = kNoStream;
      bool angle = false;
      if (is_rotation(c)) {
        s = p.rotation_stream[r++];  // kNoStream for a joint that shares its twin's rotation
        angle = true;
      } else {
        s = p.offset_stream[static_cast<int>(axis_of(c))];
      }
      if (s == kNoStream || motion.frame_count == 0) continue;  // no frames: values.data() may be null
      float* dst = out.streams_.get() + static_cast<std::size_t>(s) * out.frame_stride_;
      const double* src = motion.values.data() + first + i;
      // Angles are reduced to [-180, 180] in double before rounding to float,
      // so a file's 7200 degrees keeps the precision of 0 degrees.
      if (angle) {
        for (std::size_t f = 0; f < motion.frame_count; ++f)
          dst[f] = static_cast<float>(std::remainder(src[f * stride], 360.0));
      } else {
        for (std::size_t f = 0; f < motion.frame_count; ++f) dst[f] = static_cast<float>(src[f * stride]);
      }
    }
  }

  for (const JointPlan& p : out.plan_->joints) {
    for (int r = 0; r < p.rotation_count; ++r) {
      out.rotation_offsets_.push_back(p.rotation_stream[r] * static_cast<std::int32_t>(out.frame_stride_));
    }
  }
  out.rotation_offsets_.resize((out.rotation_offsets_.size() + kFrameAlignment - 1) / kFrameAlignment * kFrameAlignment,
                               0);

  out.build_frame_program();

  if (out.all_roots_) {
    // Without channels every frame is the same: one stored frame serves all,
    // however many frames the motion declares.
    const std::size_t stored = motion.stride() == 0 ? std::min<std::size_t>(motion.frame_count, 1) : motion.frame_count;
    out.positions_per_frame_ = motion.stride() != 0;
    out.stored_positions_.resize(stored * joints * 3);
    for (std::size_t f = 0; f < stored; ++f) {
      for (std::size_t j = 0; j < joints; ++j) {
        const Eigen::Vector3d t = motion.local_offset(f, static_cast<int>(j));
        float* dst = out.stored_positions_.data() + (f * joints + j) * 3;
        for (int a = 0; a < 3; ++a) dst[a] = static_cast<float>(t[a]);
      }
    }
  }
  return out;
}

void CompiledMotion::build_frame_program() {
  FrameProgram& prog = plan_->program;
  const std::size_t joints = plan_->joints.size();
  const auto key_of = [](const JointPlan& p) {
    return static_cast<int>(p.rotation_count) * 64 + p.axes[0] * 16 + (p.rotation_count > 1 ? p.axes[1] : 0) * 4 +
           (p.rotation_count > 2 ? p.axes[2] : 0);
  };
  // Groups of joints with the same axis order, in order of first appearance.
  std::vector<int> keys;
  std::vector<std::vector<std::size_t>> members;
  for (std::size_t j = 0; j < joints; ++j) {
    const JointPlan& p = plan_->joints[j];
    if (!p.owns_slot) continue;
    const int key = key_of(p);
    std::size_t g = 0;
    while (g < keys.size() && keys[g] != key) ++g;
    if (g == keys.size()) {
      keys.push_back(key);
      members.emplace_back();
    }
    members[g].push_back(j);
  }
  std::vector<std::int32_t> local_of(joints, -1);
  std::size_t next = 0;
  for (std::size_t g = 0; g < keys.size(); ++g) {
    const JointPlan& p0 = plan_->joints[members[g].front()];
    FrameProgram::Group group;
    group.count = static_cast<std::uint8_t>(p0.rotation_count);
    for (int r = 0; r < 3; ++r) group.axes[r] = r < p0.rotation_count ? p0.axes[r] : 0;
    group.first = static_cast<std::uint32_t>(next);
    group.size =
        static_cast<std::uint32_t>((members[g].size() + kFrameAlignment - 1) / kFrameAlignment * kFrameAlignment);
    for (std::size_t i = 0; i < members[g].size(); ++i) local_of[members[g][i]] = static_cast<std::int32_t>(next + i);
    next += group.size;
    prog.groups.push_back(group);
  }
  prog.local_count = next;
  prog.gather.assign(3 * next, 0);
  const auto world_off = [](std::int32_t slot) { return (slot + 1) * 12; };  // kIdentitySlot -> 0
  const bool pre = convention_ == Convention::kPreRotation;
  std::vector<char> has_child(joints, 0);
  for (const JointPlan& p : plan_->joints) {
    if (p.parent != kNoParent) has_child[static_cast<std::size_t>(p.parent)] = 1;
  }
  for (std::size_t j = 0; j < joints; ++j) {
    const JointPlan& p = plan_->joints[j];
    const auto jj = static_cast<std::int32_t>(j);
    if (p.parent == kNoParent) prog.roots.push_back(jj);
    if (!p.owns_slot) {
      if (p.parent == kNoParent || all_roots_) continue;  // W = identity (or its twin's), P = t: nothing to run
      // W_j is its twin's or its parent's (pre-rotation), W_p (post); both are
      // computed by an earlier step, or are the identity.
      const FrameProgram::PosOp op{p.zero_offset ? 0 : world_off(pre ? p.world_slot : p.parent_slot),
                                   (p.parent + 1) * 4, (jj + 1) * 4, jj * 4};
      if (!has_child[j]) {
        prog.leaves.push_back(op);
      } else {
        prog.ops.push_back(op);
        if (prog.steps.empty()) {
          prog.prologue = static_cast<std::uint32_t>(prog.ops.size());
        } else {
          prog.steps.back().ops_end = static_cast<std::uint32_t>(prog.ops.size());
        }
      }
      continue;
    }
    FrameProgram::Step step;
    step.t = jj * 4;
    step.from = world_off(p.parent_slot);
    step.parent = p.parent == kNoParent ? 0 : (p.parent + 1) * 4;
    step.pos = p.parent == kNoParent ? static_cast<std::int32_t>(joints + 1) * 4 : (jj + 1) * 4;
    const auto i = static_cast<std::size_t>(local_of[j]);
    for (int r = 0; r < p.rotation_count; ++r) {
      prog.gather[static_cast<std::size_t>(r) * next + i] =
          p.rotation_stream[r] * static_cast<std::int32_t>(frame_stride_);
    }
    step.out = world_off(p.world_slot);
    step.local = local_of[j];
    step.ops_begin = step.ops_end = static_cast<std::uint32_t>(prog.ops.size());
    prog.steps.push_back(step);
  }
  if (!all_roots_) {
    prog.offsets.assign(joints * 4, 0.0f);
    for (std::size_t j = 0; j < joints; ++j) {
      const JointPlan& p = plan_->joints[j];
      for (int a = 0; a < 3; ++a) {
        const auto dst = static_cast<std::int32_t>(j * 4) + a;
        if (p.offset_stream[a] == kNoStream) {
          prog.offsets[static_cast<std::size_t>(dst)] = p.offset[a];
        } else {
          prog.patches.push_back({dst, p.offset_stream[a]});
        }
      }
    }
  }
  // Frame-major copy of the angles in gather order (padding entries hold
  // what the gather reads for them: stream 0 of the frame).
  const std::size_t per_frame = 3 * next;
  if (frame_count_ > 0 && stream_count_ > 0) {
    prog.angles.reset(
        static_cast<float*>(::operator new[](frame_count_* per_frame * sizeof(float), std::align_val_t{64})));
    const float* base = streams_.get();
    for (std::size_t f = 0; f < frame_count_; ++f) {
      float* dst = prog.angles.get() + f * per_frame;
      for (std::size_t i = 0; i < per_frame; ++i) dst[i] = base[static_cast<std::size_t>(prog.gather[i]) + f];
    }
  }
  prog.workspace_floats = 15 * next + 12 * (slot_count_ + 1) + 4 * joints + 4 * (joints + 2);
}

std::size_t CompiledMotion::bytes_per_frame() const {
  return (stream_count_ + (all_roots_ && positions_per_frame_ ? joint_count() * 3 : 0)) * sizeof(float);
}

const float* CompiledMotion::stored_positions(std::size_t frame) const {
  return stored_positions_.data() + (positions_per_frame_ ? frame : 0) * joint_count_ * 3;
}

std::size_t CompiledMotion::bytes() const {
  return (stream_count_ * frame_stride_ + stored_positions_.size() +
          (plan_->program.angles ? frame_count_ * 3 * plan_->program.local_count : 0)) *
             sizeof(float) +
         plan_->joints.size() * sizeof(JointPlan);
}

}  // namespace gmr::fast
