// Humanoid roles: which joint of a skeleton sits where on a human body
// (docs/retarget.md, "Maps"). A role names a joint *position*: `left_lower_leg`
// is the knee, the joint that bends the shin, whatever the rig calls it. So a
// rig that names joints after the bone they end (CMU's ASF: `lfemur` is the
// knee) and one that names them after the bone they start (BVH: `LeftLeg` is
// the knee) map to the same roles.
#pragma once

#include <array>
#include <cstddef>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/skeleton/skeleton.h"

namespace gmr {

enum class Role : int {
  kHips,
  kSpine,
  kChest,
  kUpperChest,
  kNeck,
  kHead,
  kHeadEnd,
  kLeftShoulder,  // the clavicle's start
  kLeftUpperArm,  // the shoulder joint
  kLeftLowerArm,  // the elbow
  kLeftHand,      // the wrist
  kLeftHandEnd,   // the middle finger's base
  kRightShoulder,
  kRightUpperArm,
  kRightLowerArm,
  kRightHand,
  kRightHandEnd,
  kLeftUpperLeg,  // the hip joint
  kLeftLowerLeg,  // the knee
  kLeftFoot,      // the ankle
  kLeftToes,      // the ball of the foot
  kLeftToesEnd,
  kRightUpperLeg,
  kRightLowerLeg,
  kRightFoot,
  kRightToes,
  kRightToesEnd,
};
inline constexpr std::size_t kRoleCount = 27;

// "hips", "left_upper_arm", ...: the names maps and messages use.
std::string_view role_name(Role role);
std::optional<Role> parse_role(std::string_view name);
// The roles every humanoid map must have: hips, head, and both arms and legs
// down to hand and foot.
bool role_required(Role role);

struct HumanoidMap {
  std::array<int, kRoleCount> joint;  // joint index per role; kNoParent when the rig has none
  std::string naming;                 // the built-in naming that matched, or "map" for a given one

  int operator[](Role r) const { return joint[static_cast<std::size_t>(r)]; }
  bool has(Role r) const { return (*this)[r] >= 0; }
};

// The names of the built-in namings: cmu-asf, cmu-bvh (cgspeed MotionBuilder),
// cmu-3dsmax, daz (and cgspeed's Daz release), mixamo, character-creator,
// bandai-namco, makehuman, unreal-mannequin, unity-humanoid (also Godot's
// humanoid profile), gmr-demo (the built-in demo library).
std::vector<std::string> builtin_namings();

// The skeleton's roles. `given` (role name -> joint name, e.g. read from a
// --map JSON file) is used as it is; without it every built-in naming is
// tried (joint names compared without a `prefix:` such as `mixamorig:` and
// without case) and the one that maps the most required roles wins. Fails
// with the missing required roles named (and the naming that came closest),
// or, for a given map, naming an unknown role, a joint the skeleton does not
// have, or a joint given two roles.
Result<HumanoidMap> map_humanoid(const Skeleton& skeleton, const std::map<std::string, std::string>* given = nullptr);

}  // namespace gmr
