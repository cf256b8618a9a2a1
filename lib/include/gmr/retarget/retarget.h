// A motion put on another humanoid skeleton (docs/retarget.md): every target
// bone whose two ends have roles takes the source bone's world direction,
// twist follows the source's orientation changes from its rest pose, the hips
// take their up and left-right axes from the source's, and the root travels
// the source's path scaled by the ratio of hip heights. The output has the
// target's skeleton exactly (names, hierarchy, offsets: bone lengths), with
// rotation channels added where a driven joint had fewer than three.
#pragma once

#include <Eigen/Core>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"
#include "gmr/retarget/humanoid.h"

namespace gmr {

struct RetargetOptions {
  // Role -> joint name maps (a --map JSON file); null: the built-in namings.
  const std::map<std::string, std::string>* source_map = nullptr;
  const std::map<std::string, std::string>* target_map = nullptr;
};

// What a retarget found and decided, for `gmr retarget` and the tests.
struct RetargetPlan {
  HumanoidMap source, target;
  // Source world axes -> target world axes: both rigs' rest up (hips to head)
  // and left (right to left hip) snapped to the nearest signed axes when
  // within 30 degrees of one, so output directions are G times the source's.
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
  double scale = 1.0;  // target hip height / source hip height (reference poses)
  // The rig's up axis (hips to head at its reference, snapped like `axes`)
  // and its hip height above its lowest foot there, in the rig's units.
  Eigen::Vector3d target_up = Eigen::Vector3d::UnitY();
  double target_hip_height = 0.0;
  // The pose each rig is measured in: "rest pose" (every rotation zero) when
  // that is a standing humanoid, else "first frame" (Character Creator rigs
  // bake their bone axes into the rotations, so their rest pose is folded up;
  // their files start with a T-pose).
  std::string source_reference, target_reference;
  // Target joints that get rotations, as "joint (role -> role)" lines.
  std::vector<std::string> driven;
};

// Plans a retarget of `source` onto the rig `target` (a motion whose skeleton
// is the target; its frames are used only for a reference pose, above).
// Fails when either skeleton is not a humanoid the maps cover (naming the
// missing roles), when a role's joint is not below the previous role's (a map
// that crosses chains), or when neither the rest pose nor the first frame of
// a rig stands like a humanoid (head above hips, feet below, hips apart).
Result<RetargetPlan> plan_retarget(const Motion& source, const Motion& target, const RetargetOptions& options = {});

// A plan made once and applied to frames as they come (a live source's): made
// for `source`'s skeleton and convention (its reference pose: the rest pose,
// or its first frame), it retargets any motion on that skeleton. Thread-safe:
// apply() reads only what make() computed.
class Retargeter {
 public:
  static Result<Retargeter> make(const Motion& source, const Motion& target, const RetargetOptions& options = {});
  // The frames of `source` on the rig; fails when `source` is not on the
  // skeleton the plan was made for (fits() says).
  Result<Motion> apply(const Motion& source) const;
  // The values apply() gives (frames x output_skeleton()'s channels) without
  // building a motion around them: what a live view converts each frame.
  // Fails as apply() does, and when a value is not finite (a degenerate frame).
  Result<std::vector<double>> apply_values(const Motion& source) const;
  const Skeleton& output_skeleton() const;
  bool fits(const Motion& source) const;
  const RetargetPlan& plan() const;

 private:
  struct State;
  std::shared_ptr<const State> state_;
};

// `source`'s frames on `target`'s skeleton (post-rotation, the source's frame
// time). Joints that no role drives keep their reference-pose channels. A
// pre-rotation rig is converted to post-rotation first; one whose conversion
// would add joints is refused.
Result<Motion> retarget(const Motion& source, const Motion& target, const RetargetOptions& options = {},
                        RetargetPlan* plan_out = nullptr);

// Foot contacts (`gmr retarget --keep-contacts`; docs/retarget.md, "Foot
// contacts"). A foot rests while its ankle is within `height` hip heights
// above its floor (its height in the lowest 5% of the take's frames) and moves
// slower than `speed` hip heights per second along the floor, for at least
// `min_frames` frames; each such stretch
// gets one pin (the ankle's mean place on the floor), eased in over
// `blend_frames` frames before it and out after.
struct ContactOptions {
  double height = 0.1;
  double speed = 0.5;
  std::size_t min_frames = 3;
  std::size_t blend_frames = 5;
};

struct ContactReport {
  std::size_t contacts = 0;       // stretches pinned, both feet
  std::size_t frames_pinned = 0;  // foot-frames inside them
  // The farthest a resting ankle was from its pin along the floor, before and
  // after (rig units); after is 0 to round-off unless a pin was out of reach.
  double slide_before = 0.0, slide_after = 0.0;
  std::size_t out_of_reach = 0;  // foot-frames whose pin the straightened leg could not reach
  double lowest = 0.0;           // the most the body was lowered to reach a pin (rig units)
};

// `retargeted` (retarget()'s output, with its plan) with the resting feet
// pinned: a two-bone IK on each leg (the hip joint and the knee turn, the knee
// bending in its own plane) puts the ankle on its pin, the foot keeps its
// world orientation, every other joint keeps its rotations and every bone its
// length; where a straight leg cannot reach its pin the root is lowered along
// up just enough, eased in and out. Whole takes only: a live frame has no
// future to find a stretch in.
Result<Motion> keep_contacts(const Motion& retargeted, const RetargetPlan& plan, const ContactOptions& options = {},
                             ContactReport* report = nullptr);

}  // namespace gmr
