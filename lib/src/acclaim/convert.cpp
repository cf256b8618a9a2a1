// Acclaim <-> GMR. The Acclaim model is stated in gmr/acclaim/kinematics.h.
#include "gmr/acclaim/convert.h"

#include <cmath>
#include <string>
#include <string_view>
#include <unordered_set>

#include "acclaim_model.h"
#include "acclaim_text.h"
#include "gmr/core/file_util.h"

namespace gmr {
namespace {

// The documentation line that keeps a root's name through ASF, which names
// every root `root` (docs/asf-amc.md).
constexpr std::string_view kRootNameTag = "gmr root name: ";

// `root`, or the name a gmr-written ASF kept for its root when it is usable:
// on one line, and no bone's name (ASF names compare case-insensitively).
std::string root_name(const AsfSkeleton& s) {
  std::size_t at = 0;
  while (at < s.documentation.size()) {
    std::size_t end = s.documentation.find('\n', at);
    if (end == std::string::npos) end = s.documentation.size();
    std::string_view line(s.documentation.data() + at, end - at);
    while (!line.empty() && (line.front() == ' ' || line.front() == '\t')) line.remove_prefix(1);
    while (!line.empty() && (line.back() == ' ' || line.back() == '\t' || line.back() == '\r')) line.remove_suffix(1);
    if (line.substr(0, kRootNameTag.size()) == kRootNameTag) {
      const std::string name(line.substr(kRootNameTag.size()));
      if (name.empty() || s.find(name) > 0) return "root";
      return name;
    }
    at = end + 1;
  }
  return "root";
}

}  // namespace

using namespace acclaim_detail;

Result<Motion> acclaim_to_gmr(const AsfSkeleton& s, const AmcMotion& m, const AcclaimToGmrOptions& options) {
  const std::size_t stride_in = static_cast<std::size_t>(s.value_count());
  if (m.values.size() != m.frame_count * stride_in) {
    return make_error("AMC motion has " + std::to_string(m.values.size()) + " values, expected " +
                      std::to_string(m.frame_count) + " frames x " + std::to_string(stride_in));
  }
  if (s.bones.empty() || s.bones[0].parent >= 0) return make_error("ASF skeleton has no root");
  if (!std::isfinite(options.length_scale) || !std::isfinite(options.frame_time) || options.frame_time < 0.0) {
    return make_error("length scale and frame time must be finite (frame time >= 0)");
  }
  const double scale = options.length_scale;
  const double value_scale = m.degrees ? 1.0 : kRadToDeg;

  // How each bone's channels are laid out in the GMR joint.
  enum class RotationMode { kNone, kDirect, kDecomposed };
  struct Plan {
    RotationMode rotation = RotationMode::kNone;
    bool bone_translation = false;        // 3 position channels, per frame
    std::vector<int> root_position_dofs;  // root: index of the TX/TY/TZ values, in channel order
    std::vector<int> direct_dofs;         // kDirect: value index of each rotation channel
  };
  std::vector<Plan> plans(s.bones.size());
  std::vector<Joint> joints(s.bones.size());
  static constexpr Axis kZyx[3] = {Axis::kZ, Axis::kY, Axis::kX};
  for (std::size_t b = 0; b < s.bones.size(); ++b) {
    const AsfBone& bone = s.bones[b];
    if (bone.parent >= static_cast<int>(b)) return make_error("ASF bone '" + bone.name + "' comes before its parent");
    Joint& j = joints[b];
    Plan& p = plans[b];
    j.name = bone.parent < 0 ? root_name(s) : bone.name;
    j.parent = bone.parent;
    j.offset = bone.parent < 0 ? Eigen::Vector3d(bone.position * scale)
                               : Eigen::Vector3d(bone.direction * (bone.length * scale));
    if (!j.offset.allFinite()) {
      return make_error("ASF bone '" + bone.name + "': its offset times the length scale " + std::to_string(scale) +
                        " is not finite");
    }
    if (bone.parent < 0) {
      for (std::size_t i = 0; i < bone.dofs.size(); ++i) {
        if (is_translation_dof(bone.dofs[i])) {
          p.root_position_dofs.push_back(static_cast<int>(i));
          j.channels.push_back(position_channel(dof_axis(bone.dofs[i])));
        }
      }
    } else if (has_translation(bone)) {
      p.bone_translation = true;
      j.channels = {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition};
    }
    bool any_rotation = false;
    for (AcclaimDof d : bone.dofs) any_rotation = any_rotation || is_rotation_dof(d);
    if (!any_rotation) continue;
    if (!has_axis(bone)) {
      // C = I: L = M exactly; M applies dofs first to last, GMR composes in listed order.
      p.rotation = RotationMode::kDirect;
      for (int i = static_cast<int>(bone.dofs.size()) - 1; i >= 0; --i) {
        if (!is_rotation_dof(bone.dofs[static_cast<std::size_t>(i)])) continue;
        p.direct_dofs.push_back(i);
        j.channels.push_back(rotation_channel(dof_axis(bone.dofs[static_cast<std::size_t>(i)])));
      }
    } else {
      p.rotation = RotationMode::kDecomposed;
      for (Axis a : kZyx) j.channels.push_back(rotation_channel(a));
    }
  }
  auto skel = Skeleton::create(std::move(joints));
  if (!skel) return skel.error();

  Motion out;
  out.skeleton = std::move(*skel);
  out.convention = Convention::kPreRotation;
  out.frame_time = options.frame_time;
  out.frame_count = m.frame_count;
  const std::size_t stride = out.stride();
  out.values.assign(stride * m.frame_count, 0.0);
  const Prepared prep = prepare(s);
  std::vector<Eigen::Vector3d> previous(s.bones.size(), Eigen::Vector3d::Zero());  // continuity hints
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    for (std::size_t b = 0; b < s.bones.size(); ++b) {
      const AsfBone& bone = s.bones[b];
      const Plan& p = plans[b];
      const auto v = bone_values(s, m, f, static_cast<int>(b), prep);
      double* dst =
          out.values.data() + f * stride + static_cast<std::size_t>(out.skeleton.channel_offset(static_cast<int>(b)));
      std::size_t k = 0;
      const bool need_state = p.rotation == RotationMode::kDecomposed || p.bone_translation;
      const BoneState st = need_state ? bone_state(bone, prep.c[b], v, m.degrees) : BoneState{};
      if (bone.parent < 0) {
        for (int i : p.root_position_dofs) {
          const int a = static_cast<int>(dof_axis(bone.dofs[static_cast<std::size_t>(i)]));
          dst[k++] = (bone.position[a] + v[static_cast<std::size_t>(i)]) * scale;
        }
      } else if (p.bone_translation) {
        // GMR: P = P_p + W_p L t_j must equal P_p + W_p C t + W_p L d, so t_j = L^T C t + d.
        const Eigen::Vector3d t =
            (st.local.transpose() * (prep.c[b] * st.t) + bone.direction * (bone.length + st.extra_length)) * scale;
        dst[k++] = t.x();
        dst[k++] = t.y();
        dst[k++] = t.z();
      }
      if (p.rotation == RotationMode::kDirect) {
        for (int i : p.direct_dofs) dst[k++] = v[static_cast<std::size_t>(i)] * value_scale;
      } else if (p.rotation == RotationMode::kDecomposed) {
        const Eigen::Vector3d* hint = f > 0 ? &previous[b] : nullptr;
        const Eigen::Vector3d e = decompose_euler(st.local, kZyx, hint);
        previous[b] = e;
        dst[k++] = e[0];
        dst[k++] = e[1];
        dst[k++] = e[2];
      }
    }
  }
  // Finite inputs can still overflow (an angle of 1e307 radians in degrees).
  if (auto v = out.validate(); !v) return make_error("ASF/AMC conversion overflowed: " + v.error().message);
  return out;
}

Result<Motion> read_asf_amc(const std::filesystem::path& asf, const std::filesystem::path& amc, Warnings* out_warnings,
                            const AcclaimToGmrOptions& options) {
  auto skeleton = read_asf(asf, out_warnings);
  if (!skeleton) return skeleton.error();
  auto motion = read_amc(amc, *skeleton, out_warnings);
  if (!motion) return motion.error();
  return acclaim_to_gmr(*skeleton, *motion, options);
}

// ---- GMR -> Acclaim ---------------------------------------------------------

Result<AcclaimModel> gmr_to_acclaim(const Motion& motion) {
  using acclaim_detail::to_lower;
  if (motion.convention != Convention::kPreRotation) {
    return make_error("ASF/AMC export needs a pre-rotation (GMR) motion; convert the post-rotation motion first");
  }
  if (auto v = motion.validate(); !v) return v.error();
  const Skeleton& sk = motion.skeleton;
  if (sk.empty()) return make_error("ASF/AMC export needs at least one joint");
  if (sk.roots().size() != 1) {
    return make_error("ASF holds a single tree; this motion has " + std::to_string(sk.roots().size()) +
                      " roots (join them first)");
  }
  std::unordered_set<std::string> names;
  for (std::size_t j = 0; j < sk.size(); ++j) {
    const std::string& n = sk.joint(static_cast<int>(j)).name;
    if (sk.is_root(static_cast<int>(j))) continue;  // written as `root`
    bool ok = !n.empty() && n.front() != ':';
    for (char c : n) ok = ok && !(acclaim_detail::is_separator(c) || c == '#' || c == '\n' || c == '\r');
    if (!ok)
      return make_error("joint name '" + n + "' cannot be written to ASF (empty, whitespace, `,()#` or a leading ':')");
    const std::string key = to_lower(n);
    if (key == "root" || key == "begin" || key == "end") {
      return make_error("joint '" + n + "' cannot be written to ASF: '" + key + "' is reserved for " +
                        (key == "root" ? "the root" : "the hierarchy's keywords"));
    }
    if (!names.insert(key).second)
      return make_error("joint names differ only in case ('" + n + "'); ASF names are case-insensitive");
  }

  // Bones in depth-first order (the order parse_asf gives back).
  const int root = sk.roots()[0];
  std::vector<int> order;
  std::vector<int> stack{root};
  while (!stack.empty()) {
    const int j = stack.back();
    stack.pop_back();
    order.push_back(j);
    const auto kids = sk.children(j);
    for (auto it = kids.rbegin(); it != kids.rend(); ++it) stack.push_back(*it);
  }
  std::vector<int> bone_of(sk.size(), -1);
  for (std::size_t i = 0; i < order.size(); ++i) bone_of[static_cast<std::size_t>(order[i])] = static_cast<int>(i);

  AcclaimModel out;
  AsfSkeleton& as = out.skeleton;
  as.version = "1.10";
  as.name = "gmr";
  as.units = AsfUnits{};  // mass 1, length 1, degrees
  as.documentation = "written by gmr from a GMR (pre-rotation) motion";
  // ASF calls its root `root`; the joint's own name stays in the
  // documentation, where acclaim_to_gmr finds it again.
  if (const std::string& rn = sk.joint(root).name; rn != "root" && rn.find_first_of("\r\n") == std::string::npos)
    as.documentation += "\n" + std::string(kRootNameTag) + rn;
  // For each bone: which channel feeds each dof value (-1 = computed translation).
  std::vector<std::vector<int>> sources(order.size());
  for (std::size_t i = 0; i < order.size(); ++i) {
    const int j = order[i];
    const Joint& joint = sk.joint(j);
    AsfBone b;
    b.id = static_cast<int>(i);
    b.parent = joint.parent < 0 ? -1 : bone_of[static_cast<std::size_t>(joint.parent)];
    auto& src = sources[i];
    if (joint.parent < 0) {
      b.name = "root";
      b.position = joint.offset;
      for (std::size_t c = 0; c < joint.channels.size(); ++c) {
        if (!is_position(joint.channels[c])) continue;
        const Axis a = axis_of(joint.channels[c]);
        b.position[static_cast<int>(a)] = 0.0;
        b.dofs.push_back(a == Axis::kX ? AcclaimDof::kTx : a == Axis::kY ? AcclaimDof::kTy : AcclaimDof::kTz);
        src.push_back(static_cast<int>(c));
      }
    } else {
      b.name = joint.name;
      b.length = joint.offset.norm();
      b.direction = b.length > 0.0 ? Eigen::Vector3d(joint.offset / b.length) : Eigen::Vector3d(0, 0, 1);
      if (joint.has_translation()) {
        b.dofs = {AcclaimDof::kTx, AcclaimDof::kTy, AcclaimDof::kTz};
        src = {-1, -1, -1};
      }
    }
    // GMR composes rotation channels in listed order; Acclaim applies dofs first to last.
    for (int c = static_cast<int>(joint.channels.size()) - 1; c >= 0; --c) {
      const ChannelType ch = joint.channels[static_cast<std::size_t>(c)];
      if (!is_rotation(ch)) continue;
      const Axis a = axis_of(ch);
      b.dofs.push_back(a == Axis::kX ? AcclaimDof::kRx : a == Axis::kY ? AcclaimDof::kRy : AcclaimDof::kRz);
      src.push_back(c);
    }
    as.bones.push_back(std::move(b));
  }

  AmcMotion& am = out.motion;
  am.fully_specified = true;
  am.degrees = true;
  am.frame_count = motion.frame_count;
  const std::size_t stride = static_cast<std::size_t>(as.value_count());
  am.values.assign(stride * motion.frame_count, 0.0);
  am.frame_numbers.resize(motion.frame_count);
  for (std::size_t f = 0; f < motion.frame_count; ++f) {
    am.frame_numbers[f] = static_cast<long long>(f) + 1;
    std::size_t k = f * stride;
    for (std::size_t i = 0; i < order.size(); ++i) {
      const int j = order[i];
      const auto v = motion.joint_values(f, j);
      const auto& src = sources[i];
      Eigen::Vector3d t = Eigen::Vector3d::Zero();
      if (!src.empty() && src[0] == -1) {
        // Acclaim (C = I): P = P_p + W_p t + W_p R d; GMR: P = P_p + W_p R t_j. So t = R (t_j - d).
        const AsfBone& b = as.bones[i];
        const Eigen::Matrix3d r = motion.local_rotation(f, j);
        t = r * (motion.local_offset(f, j) - b.direction * b.length);
      }
      for (std::size_t d = 0; d < src.size(); ++d) {
        am.values[k++] = src[d] >= 0 ? v[static_cast<std::size_t>(src[d])] : t[static_cast<int>(d)];
      }
    }
  }
  return out;
}

Status write_asf_amc(const Motion& motion, const std::filesystem::path& asf, const std::filesystem::path& amc,
                     bool replace_other_asf) {
  auto model = gmr_to_acclaim(motion);
  if (!model) return model.error();
  // Format both before writing either, so a failure leaves no half-written pair.
  const std::string asf_text = format_asf(model->skeleton);
  auto amc_text = format_amc(model->skeleton, model->motion);
  if (!amc_text) return amc_text.error();
  if (!replace_other_asf) {
    std::error_code ec;
    if (std::filesystem::exists(asf, ec)) {
      auto old = read_file(asf);
      if (!old || *old != asf_text) {
        return Error{asf.string(), 0, 0,
                     "exists and holds another skeleton (other .amc files may use it): not replaced; write the "
                     "skeleton elsewhere, or replace it on purpose",
                     ErrorKind::kFailedPrecondition};
      }
    }
  }
  // The skeleton is renamed into place first: an .amc never stands beside a
  // skeleton older than itself.
  const FileContent pair[] = {{asf, asf_text}, {amc, *amc_text}};
  return write_files_atomic(pair);
}

}  // namespace gmr
