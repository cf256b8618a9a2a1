#include "gmr/retarget/humanoid.h"

#include <algorithm>
#include <cctype>

namespace gmr {
namespace {

constexpr std::array<std::string_view, kRoleCount> kRoleNames = {
    "hips",       "spine",          "chest",           "upper_chest",     "neck",
    "head",       "head_end",       "left_shoulder",   "left_upper_arm",  "left_lower_arm",
    "left_hand",  "left_hand_end",  "right_shoulder",  "right_upper_arm", "right_lower_arm",
    "right_hand", "right_hand_end", "left_upper_leg",  "left_lower_leg",  "left_foot",
    "left_toes",  "left_toes_end",  "right_upper_leg", "right_lower_leg", "right_foot",
    "right_toes", "right_toes_end"};

// One naming: per role (in Role order) the joint names it may have, '|'
// between alternatives, "" for none. Joints are compared without a "prefix:"
// and without case.
struct Naming {
  std::string_view name;
  std::array<std::string_view, kRoleCount> roles;
};

// clang-format off
constexpr Naming kNamings[] = {
    // CMU's ASF names a joint after the bone that ends there: lfemur is the knee.
    {"cmu-asf", {"root", "lowerback", "upperback", "", "thorax", "upperneck", "head",
                 "", "lclavicle", "lhumerus", "lradius", "lhand",
                 "", "rclavicle", "rhumerus", "rradius", "rhand",
                 "lhipjoint", "lfemur", "ltibia", "lfoot", "ltoes",
                 "rhipjoint", "rfemur", "rtibia", "rfoot", "rtoes"}},
    // cgspeed's MotionBuilder-friendly BVH (cmu/), End Sites as gmr names them.
    {"cmu-bvh", {"Hips", "Spine", "Spine1", "", "Neck", "Head", "Head_End",
                 "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftFingerBase|LFingers",
                 "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightFingerBase|RFingers",
                 "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToeBase_End",
                 "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightToeBase_End"}},
    {"cmu-3dsmax", {"Hips", "Chest", "Chest2", "", "lowerneck", "Head", "Head_End",
                    "LeftCollar", "LeftShoulder", "LeftElbow", "LeftWrist", "lhand",
                    "RightCollar", "RightShoulder", "RightElbow", "RightWrist", "rhand",
                    "LeftHip", "LeftKnee", "LeftAnkle", "LeftToe", "LeftToe_End",
                    "RightHip", "RightKnee", "RightAnkle", "RightToe", "RightToe_End"}},
    {"daz", {"hip", "abdomen", "chest", "", "neck", "head", "head_End",
             "lCollar", "lShldr", "lForeArm", "lHand", "lMid1",
             "rCollar", "rShldr", "rForeArm", "rHand", "rMid1",
             "lThigh", "lShin", "lFoot", "", "lFoot_End",
             "rThigh", "rShin", "rFoot", "", "rFoot_End"}},
    {"mixamo", {"Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", "HeadTop_End|Head_End",
                "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftHandMiddle1",
                "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightHandMiddle1",
                "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToe_End|LeftToeBase_End",
                "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightToe_End|RightToeBase_End"}},
    {"character-creator", {"CC_Base_Hip", "CC_Base_Waist", "CC_Base_Spine01", "CC_Base_Spine02",
                           "CC_Base_NeckTwist01", "CC_Base_Head", "",
                           "CC_Base_L_Clavicle", "CC_Base_L_Upperarm", "CC_Base_L_Forearm", "CC_Base_L_Hand",
                           "CC_Base_L_Mid1",
                           "CC_Base_R_Clavicle", "CC_Base_R_Upperarm", "CC_Base_R_Forearm", "CC_Base_R_Hand",
                           "CC_Base_R_Mid1",
                           "CC_Base_L_Thigh", "CC_Base_L_Calf", "CC_Base_L_Foot", "CC_Base_L_ToeBase", "",
                           "CC_Base_R_Thigh", "CC_Base_R_Calf", "CC_Base_R_Foot", "CC_Base_R_ToeBase", ""}},
    {"bandai-namco", {"Hips", "Spine", "Chest", "", "Neck", "Head", "Head_End",
                      "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L", "Hand_L_End",
                      "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R", "Hand_R_End",
                      "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "Toes_L_End",
                      "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R", "Toes_R_End"}},
    {"makehuman", {"root", "spine04", "spine02", "spine01", "neck01", "head", "",
                   "clavicle.L", "upperarm01.L", "lowerarm01.L", "wrist.L", "",
                   "clavicle.R", "upperarm01.R", "lowerarm01.R", "wrist.R", "",
                   "upperleg01.L", "lowerleg01.L", "foot.L", "", "",
                   "upperleg01.R", "lowerleg01.R", "foot.R", "", ""}},
    {"unreal-mannequin", {"pelvis", "spine_01", "spine_02", "spine_03", "neck_01", "head", "",
                          "clavicle_l", "upperarm_l", "lowerarm_l", "hand_l", "middle_01_l",
                          "clavicle_r", "upperarm_r", "lowerarm_r", "hand_r", "middle_01_r",
                          "thigh_l", "calf_l", "foot_l", "ball_l", "",
                          "thigh_r", "calf_r", "foot_r", "ball_r", ""}},
    // gmr's own built-in demo library (gmr demo, gmr-server without --library).
    {"gmr-demo", {"pelvis", "spine", "chest", "", "neck", "head", "head_top",
                  "", "l_shoulder", "l_elbow", "l_wrist", "l_hand",
                  "", "r_shoulder", "r_elbow", "r_wrist", "r_hand",
                  "l_hip", "l_knee", "l_ankle", "l_toe", "",
                  "r_hip", "r_knee", "r_ankle", "r_toe", ""}},
    // Unity's humanoid avatar; Godot's humanoid skeleton profile uses the same names.
    {"unity-humanoid", {"Hips", "Spine", "Chest", "UpperChest", "Neck", "Head", "",
                        "LeftShoulder", "LeftUpperArm", "LeftLowerArm", "LeftHand", "LeftMiddleProximal",
                        "RightShoulder", "RightUpperArm", "RightLowerArm", "RightHand", "RightMiddleProximal",
                        "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes", "",
                        "RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToes", ""}},
};
// clang-format on

std::string folded(std::string_view name) {
  const auto colon = name.rfind(':');
  if (colon != std::string_view::npos) name.remove_prefix(colon + 1);
  std::string s(name);
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

// The part of the first joint's name up to and with its first '_' when every
// joint's name starts with it and goes on after it: "mixamorig_" or "Beta_"
// where an engine replaced a Mixamo prefix's ':' (Godot refuses ':' in bone
// names); else empty.
std::string shared_underscore_prefix(const Skeleton& skeleton) {
  if (skeleton.empty()) return {};
  const std::string& first = skeleton.joint(0).name;
  const auto bar = first.find('_');
  if (bar == std::string::npos || bar == 0) return {};
  const std::string prefix = first.substr(0, bar + 1);
  for (const Joint& j : skeleton.joints()) {
    if (!j.name.starts_with(prefix) || j.name.size() == prefix.size()) return {};
  }
  return prefix;
}

// Folded names -> joints; with a shared '_' prefix, the names without it
// too, after every full name (a full name wins: `CC_Base_Hip` is matched
// whole, never as `Base_Hip`).
std::map<std::string, int> folded_index(const Skeleton& skeleton) {
  std::map<std::string, int> index;
  for (int j = 0; j < static_cast<int>(skeleton.size()); ++j) index.emplace(folded(skeleton.joint(j).name), j);
  const std::string prefix = shared_underscore_prefix(skeleton);
  if (prefix.empty()) return index;
  for (int j = 0; j < static_cast<int>(skeleton.size()); ++j) {
    index.emplace(folded(std::string_view(skeleton.joint(j).name).substr(prefix.size())), j);
  }
  return index;
}

HumanoidMap apply_naming(const Naming& naming, const std::map<std::string, int>& index) {
  HumanoidMap m;
  m.joint.fill(kNoParent);
  m.naming = std::string(naming.name);
  for (std::size_t r = 0; r < kRoleCount; ++r) {
    std::string_view alternatives = naming.roles[r];
    while (!alternatives.empty()) {
      const auto bar = alternatives.find('|');
      const std::string_view candidate = alternatives.substr(0, bar);
      alternatives = bar == std::string_view::npos ? std::string_view() : alternatives.substr(bar + 1);
      if (const auto it = index.find(folded(candidate)); it != index.end()) {
        m.joint[r] = it->second;
        break;
      }
    }
  }
  return m;
}

std::vector<std::string> missing_required(const HumanoidMap& m) {
  std::vector<std::string> missing;
  for (std::size_t r = 0; r < kRoleCount; ++r) {
    if (role_required(static_cast<Role>(r)) && m.joint[r] < 0) missing.emplace_back(kRoleNames[r]);
  }
  return missing;
}

std::string joined(const std::vector<std::string>& names) {
  std::string s;
  for (const auto& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

}  // namespace

std::string_view role_name(Role role) { return kRoleNames[static_cast<std::size_t>(role)]; }

std::optional<Role> parse_role(std::string_view name) {
  for (std::size_t r = 0; r < kRoleCount; ++r) {
    if (kRoleNames[r] == name) return static_cast<Role>(r);
  }
  return std::nullopt;
}

bool role_required(Role role) {
  switch (role) {
    case Role::kHips:
    case Role::kHead:
    case Role::kLeftUpperArm:
    case Role::kLeftLowerArm:
    case Role::kLeftHand:
    case Role::kRightUpperArm:
    case Role::kRightLowerArm:
    case Role::kRightHand:
    case Role::kLeftUpperLeg:
    case Role::kLeftLowerLeg:
    case Role::kLeftFoot:
    case Role::kRightUpperLeg:
    case Role::kRightLowerLeg:
    case Role::kRightFoot:
      return true;
    default:
      return false;
  }
}

std::vector<std::string> builtin_namings() {
  std::vector<std::string> names;
  for (const Naming& n : kNamings) names.emplace_back(n.name);
  return names;
}

Result<HumanoidMap> map_humanoid(const Skeleton& skeleton, const std::map<std::string, std::string>* given) {
  if (given != nullptr) {
    HumanoidMap m;
    m.joint.fill(kNoParent);
    m.naming = "map";
    std::map<int, std::string> taken;  // joint -> role
    for (const auto& [role_text, joint_name] : *given) {
      const auto role = parse_role(role_text);
      if (!role)
        return make_error("the map names an unknown role '" + role_text +
                          "' (roles: hips, spine, ..., see docs/retarget.md)");
      const int j = skeleton.find(joint_name);
      if (j < 0)
        return make_error("the map gives role '" + role_text + "' to '" + joint_name +
                          "', which the skeleton does not have");
      if (const auto it = taken.find(j); it != taken.end()) {
        return make_error("the map gives joint '" + joint_name + "' two roles: " + it->second + " and " + role_text);
      }
      taken.emplace(j, role_text);
      m.joint[static_cast<std::size_t>(*role)] = j;
    }
    if (const auto missing = missing_required(m); !missing.empty()) {
      return make_error("the map leaves required roles without a joint: " + joined(missing));
    }
    return m;
  }
  const auto index = folded_index(skeleton);
  std::optional<HumanoidMap> best;
  std::size_t best_required = 0, best_all = 0;
  for (const Naming& naming : kNamings) {
    HumanoidMap m = apply_naming(naming, index);
    std::size_t required = 0, all = 0;
    for (std::size_t r = 0; r < kRoleCount; ++r) {
      if (m.joint[r] < 0) continue;
      ++all;
      if (role_required(static_cast<Role>(r))) ++required;
    }
    if (!best || required > best_required || (required == best_required && all > best_all)) {
      best = std::move(m);
      best_required = required;
      best_all = all;
    }
  }
  if (best_required == 0) {
    return make_error("not a humanoid any built-in naming knows (" + joined(builtin_namings()) +
                      "): no required role found among its " + std::to_string(skeleton.size()) +
                      " joints; give --map with role -> joint names (docs/retarget.md)");
  }
  if (const auto missing = missing_required(*best); !missing.empty()) {
    return make_error("closest naming " + best->naming + " leaves required roles without a joint: " + joined(missing) +
                      "; give --map (docs/retarget.md)");
  }
  return *best;
}

}  // namespace gmr
