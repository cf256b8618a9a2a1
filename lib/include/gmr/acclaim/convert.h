// Acclaim <-> GMR: an ASF/AMC pair as a GMR (pre-rotation) motion and back.
// Conversion to GMR is exact in positions: a bone's joint sits at the bone's
// tip, named after the bone; the root joint is `root` (or the name a gmr-written
// ASF kept for it: see gmr_to_acclaim).
#pragma once

#include <filesystem>

#include "gmr/acclaim/amc.h"
#include "gmr/acclaim/asf.h"
#include "gmr/core/error.h"
#include "gmr/motion/motion.h"

namespace gmr {

struct AcclaimToGmrOptions {
  double frame_time = 1.0 / 120.0;  // AMC has no frame rate; CMU captures at 120 Hz
  double length_scale = 1.0;        // multiplies lengths and translations (1: file units)
};

// Acclaim -> GMR (pre-rotation), one joint per bone in skeleton.bones order
// (joint j = bone j, the root is `root`, unless the documentation holds a line
// `gmr root name: NAME` that names no bone: then NAME):
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
// (pre-rotation) motion with acclaim_to_gmr (AMC files hold no frame rate:
// options.frame_time, 1/120 s unless said otherwise).
Result<Motion> read_asf_amc(const std::filesystem::path& asf, const std::filesystem::path& amc,
                            Warnings* out_warnings = nullptr, const AcclaimToGmrOptions& options = {});

struct AcclaimModel {
  AsfSkeleton skeleton;
  AmcMotion motion;
};

// GMR (pre-rotation) -> Acclaim, for a motion with a single root:
// - the root becomes `root` (ASF's name for it; the joint's own name goes to a
//   documentation line `gmr root name: NAME`, which acclaim_to_gmr reads back):
//   position = its offset with the components that
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

// gmr_to_acclaim, then writes both files as a pair (write_files_atomic: both
// temporaries first, then the .asf renamed into place, then the .amc). With
// replace_other_asf false, an existing `asf` whose content differs from the
// new skeleton is an error (kFailedPrecondition) and nothing is written:
// other .amc files may use it.
Status write_asf_amc(const Motion& motion, const std::filesystem::path& asf, const std::filesystem::path& amc,
                     bool replace_other_asf = true);

}  // namespace gmr
