// Acclaim ASF: the skeleton file (bones, their axes, dofs and limits), read
// and written. The Acclaim model the values obey is stated in
// gmr/acclaim/kinematics.h; AMC motions are in gmr/acclaim/amc.h.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/core/rotation.h"

namespace gmr {

// One degree of freedom of an Acclaim bone (or an entry of the root's `order`).
enum class AcclaimDof : std::uint8_t { kRx, kRy, kRz, kTx, kTy, kTz, kL };

// "rx" ... "l" (the ASF spelling; the root's `order` uses upper case).
std::string_view acclaim_dof_name(AcclaimDof dof);

struct AsfUnits {
  double mass = 1.0;
  double length = 1.0;  // recorded, not applied (see the top of this file)
  bool degrees = true;  // `angle deg` (true) or `angle rad`
};

struct AsfLimit {
  double min = 0.0;  // may be -inf
  double max = 0.0;  // may be +inf
};

// A bone. bones[0] of an AsfSkeleton is always the root: name "root",
// parent -1, dofs = its `order`, axis = its `orientation`, axis_order = its
// `axis`, position = its `position`, direction 0 and length 0.
struct AsfBone {
  int id = 0;                                           // `id` from the file (0 for the root)
  std::string name;                                     // as written; matched case-insensitively
  int parent = -1;                                      // index into AsfSkeleton::bones; -1 for the root
  Eigen::Vector3d direction = Eigen::Vector3d::Zero();  // global, rest pose
  double length = 0.0;
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();                // x, y, z angles in the ASF's angle unit
  std::array<Axis, 3> axis_order{Axis::kX, Axis::kY, Axis::kZ};  // order the axis angles apply in
  std::vector<AcclaimDof> dofs;                                  // AMC value order
  std::vector<AsfLimit> limits;                                  // as read; empty, or one per dof
  Eigen::Vector3d position = Eigen::Vector3d::Zero();            // root only
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
  // Index of bone b's first value within one AMC frame (linear in b: loops
  // over bones sum dof counts instead).
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

// ASF / AMC text. Numbers are written in their shortest round-tripping form, so
// read -> write -> read reproduces the skeleton and the values exactly. Bones
// are written in skeleton order; limits only for bones that have them.
std::string format_asf(const AsfSkeleton& skeleton);
// Atomic write (temporary file, then rename).
Status write_asf(const AsfSkeleton& skeleton, const std::filesystem::path& path);

}  // namespace gmr
