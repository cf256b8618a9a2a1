// Acclaim ASF (skeleton) and AMC (motion): read, write, forward kinematics of
// the Acclaim model itself, and conversion to and from GMR.
//
// The Acclaim model (CMU mocap semantics, as in CMU's mocapPlayer and the
// amc_parser conventions), for a bone b with parent p:
//
//   C_b  = axis rotation: the `axis a b c ORDER` values are the x, y, z angles;
//          they are applied in ORDER ("XYZ": first about x), so C = Rz*Ry*Rx.
//   M_b  = the dof rotations in `dof` order, applied first to last
//          ("dof rx ry rz" gives M = Rz*Ry*Rx; "dof rz rx" gives M = Rx*Rz).
//   L_b  = C_b * M_b * C_b^-1            (local rotation)
//   W_b  = W_p * L_b                      (world rotation; W_root = L_root)
//   tip_b = tip_p + W_p * C_b * t_b + W_b * direction_b * (length_b + l_b)
//
// where t_b = (tx, ty, tz) dof values (0 when absent; a translation in the
// bone's axis frame, not rotated by M_b) and l_b the `l` dof (0 when absent;
// added to the length). The root: C_root from `orientation` (in the root's
// `axis` order), M_root from the RX/RY/RZ entries of `order` (in that order),
// and its position = `position` + (TX, TY, TZ) in world axes.
//
// Directions are global (rest pose) and used as written (not normalised).
// Lengths and translations are in file units (`units length` is recorded but
// not applied: for CMU files, 1 unit = (1/0.45) inch = 5.644 cm, and CMU's BVH
// conversions use the same units, scale 1). Angles follow `units angle` in
// the ASF and :DEGREES / :RADIANS in the AMC (default: the ASF's unit).
//
// Conversion to GMR (pre-rotation) is exact in positions: a bone's joint sits at
// the bone's tip, named after the bone; the root joint is `root`.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/core/rotation.h"
#include "gmr/motion/motion.h"

namespace gmr {

// One degree of freedom of an Acclaim bone (or an entry of the root's `order`).
enum class AcclaimDof : std::uint8_t { kRx, kRy, kRz, kTx, kTy, kTz, kL };

// "rx" ... "l" (the ASF spelling; the root's `order` uses upper case).
std::string_view acclaim_dof_name(AcclaimDof dof);

struct AsfUnits {
  double mass = 1.0;
  double length = 1.0;    // recorded, not applied (see the top of this file)
  bool degrees = true;    // `angle deg` (true) or `angle rad`
};

struct AsfLimit {
  double min = 0.0;       // may be -inf
  double max = 0.0;       // may be +inf
};

// A bone. bones[0] of an AsfSkeleton is always the root: name "root",
// parent -1, dofs = its `order`, axis = its `orientation`, axis_order = its
// `axis`, position = its `position`, direction 0 and length 0.
struct AsfBone {
  int id = 0;                                     // `id` from the file (0 for the root)
  std::string name;                               // as written; matched case-insensitively
  int parent = -1;                                // index into AsfSkeleton::bones; -1 for the root
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();  // global, rest pose
  double length = 0.0;
  Eigen::Vector3d axis = Eigen::Vector3d::Zero(); // x, y, z angles in the ASF's angle unit
  std::array<Axis, 3> axis_order{Axis::kX, Axis::kY, Axis::kZ};  // order the axis angles apply in
  std::vector<AcclaimDof> dofs;                   // AMC value order
  std::vector<AsfLimit> limits;                   // as read; empty, or one per dof
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // root only
};

struct AsfSkeleton {
  std::string version;        // `:version`, empty when absent
  std::string name;           // `:name`, empty when absent
  std::string documentation;  // `:documentation` lines, joined with '\n'
  AsfUnits units;
  // Root first, then every bone in depth-first order of the hierarchy (each
  // parent before its children; siblings in hierarchy order). The order of
  // `:bonedata` in the file is not kept.
  std::vector<AsfBone> bones;

  // Index of the bone named `name` (case-insensitive; "root" is 0), or -1.
  int find(std::string_view name) const;
  // Number of AMC values per frame (sum of every bone's dof count).
  int value_count() const;
  // Index of bone b's first value within one AMC frame.
  int value_offset(int b) const;
};

// Parses ASF text. `file_label` names the source in errors. Fails with
// file:line:column and what was expected for: a malformed or missing number,
// an unknown dof or axis order, a bone without name/direction/length, a
// repeated bone name (case-insensitive, `root` included), a bone named `begin`,
// `end` or starting with ':' (hierarchy keywords), limits not matching
// the dofs, a hierarchy naming an unknown bone, giving a bone two parents or
// leaving one out, and a file that ends inside a block. Unknown sections and
// keywords are skipped with a warning.
Result<AsfSkeleton> parse_asf(std::string_view text, std::string_view file_label, Warnings* out_warnings = nullptr);
Result<AsfSkeleton> read_asf(const std::filesystem::path& path, Warnings* out_warnings = nullptr);

struct AmcMotion {
  bool fully_specified = false;   // `:FULLY-SPECIFIED` was present
  bool degrees = true;            // value unit: :DEGREES / :RADIANS, else the ASF's unit
  std::vector<long long> frame_numbers;  // as written (need not start at 1 or be gapless)
  std::size_t frame_count = 0;
  // Frame-major, skeleton.value_count() per frame, each bone's values at
  // skeleton.value_offset(b) in its dof order; angles in the AMC's unit.
  std::vector<double> values;

  std::span<const double> frame(std::size_t f, std::size_t stride) const {
    return std::span<const double>(values).subspan(f * stride, stride);
  }
};

// Parses AMC text against `skeleton`. Frames are kept in file order. A bone
// with dofs that a frame does not list keeps the value 0 in that frame (its
// rest pose, as CMU's mocapPlayer and amc_parser do) and one warning per file
// says so. Frame numbers that jump (gaps) give a warning. Fails with
// file:line:column for: a bone unknown to the skeleton, a bone listed twice in
// one frame, a wrong number of values, a malformed number, non-finite values,
// data before the first frame number, frame numbers that do not increase, and
// a file with no frame.
Result<AmcMotion> parse_amc(std::string_view text, std::string_view file_label, const AsfSkeleton& skeleton,
                            Warnings* out_warnings = nullptr);
Result<AmcMotion> read_amc(const std::filesystem::path& path, const AsfSkeleton& skeleton,
                           Warnings* out_warnings = nullptr);

// Local rotation L_b = C_b M_b C_b^-1 of bone b for one frame's AMC values.
Eigen::Matrix3d acclaim_local_rotation(const AsfSkeleton& skeleton, const AmcMotion& motion, std::size_t frame,
                                       int b);

// Forward kinematics of the Acclaim model (double): for every bone, the
// position of its tip (the root: its position) and, if out_orientations is not
// empty, its world rotation W_b. Both spans have skeleton.bones.size() entries.
// Requires frame < motion.frame_count.
void acclaim_compute_frame(const AsfSkeleton& skeleton, const AmcMotion& motion, std::size_t frame,
                           std::span<Eigen::Vector3d> out_positions, std::span<Eigen::Matrix3d> out_orientations = {});
// Positions of every frame, frame-major (bones.size() per frame).
std::vector<Eigen::Vector3d> acclaim_positions(const AsfSkeleton& skeleton, const AmcMotion& motion);

struct AcclaimToGmrOptions {
  double frame_time = 1.0 / 120.0;  // AMC has no frame rate; CMU captures at 120 Hz
  double length_scale = 1.0;        // multiplies lengths and translations (1: file units)
};

// Acclaim -> GMR (pre-rotation), one joint per bone in skeleton.bones order
// (joint j = bone j, the root is `root`):
// - offset = direction * length * length_scale (root: position * length_scale);
// - rotation channels: none for a bone with no rotation dof; when the axis is
//   zero (C = I) the dof rotations themselves, listed in reverse dof order
//   (values copied, converted to degrees: lossless); otherwise three channels
//   Zrotation Yrotation Xrotation from decompose_euler of L_b, continuous from
//   frame to frame;
// - position channels (X, Y, Z) on the root for its TX/TY/TZ entries, and on a
//   bone with tx/ty/tz/l dofs (all three, per frame).
// Positions from acclaim_positions() and from FK of the result agree to
// round-off. Fails when motion.values does not fit the skeleton, when the
// options are not finite, or when the bones cannot form a GMR skeleton (a bone
// before its parent: parse_asf never gives that).
Result<Motion> acclaim_to_gmr(const AsfSkeleton& skeleton, const AmcMotion& motion,
                              const AcclaimToGmrOptions& options = {});

// Reads an ASF skeleton and an AMC motion and converts them to a GMR
// (pre-rotation) motion with acclaim_to_gmr (default options).
Result<Motion> read_asf_amc(const std::filesystem::path& asf, const std::filesystem::path& amc,
                            Warnings* out_warnings = nullptr);

// ASF / AMC text. Numbers are written in their shortest round-tripping form, so
// read -> write -> read reproduces the skeleton and the values exactly. Bones
// are written in skeleton order; limits only for bones that have them.
std::string format_asf(const AsfSkeleton& skeleton);
// Writes :FULLY-SPECIFIED, the angle unit, then every frame with its number and
// every bone that has dofs. Fails when values does not hold frame_count frames.
Result<std::string> format_amc(const AsfSkeleton& skeleton, const AmcMotion& motion);
// Atomic writes (temporary file, then rename).
Status write_asf(const AsfSkeleton& skeleton, const std::filesystem::path& path);
Status write_amc(const AsfSkeleton& skeleton, const AmcMotion& motion, const std::filesystem::path& path);

struct AcclaimModel {
  AsfSkeleton skeleton;
  AmcMotion motion;
};

// GMR (pre-rotation) -> Acclaim, for a motion with a single root:
// - the root becomes `root`: position = its offset with the components that
//   have position channels set to 0, order = TX/TY/TZ for its position
//   channels then RX/RY/RZ for its rotation channels in reverse;
// - every other joint becomes a bone named after it: direction = offset /
//   |offset| (0 0 1 for a zero offset), length = |offset|, axis 0 0 0 XYZ, dofs
//   = its rotation channels in reverse order (so M equals the GMR rotation),
//   plus tx ty tz when it has position channels (their values are then
//   computed per frame; positions agree to round-off).
// Degrees, frames numbered from 1; the frame time is lost (AMC has none).
// Fails for a post-rotation motion (convert it first), several roots, a joint
// other than the root named `root`, `begin` or `end` (case-insensitive), names
// that differ only in case, and names the ASF syntax cannot hold (empty,
// whitespace, `,()#`, a leading ':').
Result<AcclaimModel> gmr_to_acclaim(const Motion& motion);

// gmr_to_acclaim, then writes both files atomically.
Status write_asf_amc(const Motion& motion, const std::filesystem::path& asf, const std::filesystem::path& amc);

}  // namespace gmr
