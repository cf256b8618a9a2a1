// Links the installed gmr::gmr: builds the demo walk in code (no file is read),
// compiles it for the fast path and checks one frame of SIMD forward
// kinematics against the double reference. Prints what it computed; exit 1
// when something fails.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <vector>

#include "gmr/demo/demo_library.h"
#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/kinematics/forward_kinematics.h"

int main() {
  const std::vector<gmr::NamedMotion> library = gmr::demo_library();
  if (library.empty()) {
    std::fprintf(stderr, "empty demo library\n");
    return 1;
  }
  const gmr::NamedMotion& demo = library.front();
  gmr::Result<gmr::fast::CompiledMotion> compiled = gmr::fast::CompiledMotion::compile(demo.motion);
  if (!compiled.ok()) {
    std::fprintf(stderr, "compile: %s\n", compiled.error().message.c_str());
    return 1;
  }
  const gmr::fast::CompiledMotion& motion = *compiled;
  const std::size_t joints = motion.joint_count();
  const std::size_t frame = motion.frame_count() / 2;

  std::vector<float> positions(joints * 3);
  std::vector<float> workspace(gmr::fast::fk_workspace_size(motion));
  gmr::fast::FkFrameJob job;
  job.motion = &motion;
  job.frame = frame;
  job.out_positions = positions;
  job.workspace = workspace;
  if (!job.run()) {
    std::fprintf(stderr, "FkFrameJob: %s\n", job.check().error().message.c_str());
    return 1;
  }

  std::printf("gmr consumer: %s, %zu joints, %zu frames, frame %zu, SIMD %s\n", demo.name.c_str(), joints,
              motion.frame_count(), frame, gmr::fast::simd_target_name());
  const std::vector<Eigen::Vector3d> reference = gmr::compute_positions(demo.motion, frame, frame + 1);
  double max_error = 0.0;
  for (std::size_t j = 0; j < joints; ++j) {
    for (int axis = 0; axis < 3; ++axis) {
      max_error = std::max(max_error, std::abs(reference[j][axis] - static_cast<double>(positions[j * 3 + axis])));
    }
    if (j < 3) {
      std::printf("%s %.3f %.3f %.3f\n", demo.motion.skeleton.joint(static_cast<int>(j)).name.c_str(), positions[j * 3],
                  positions[j * 3 + 1], positions[j * 3 + 2]);
    }
  }
  const double tolerance = 1e-4 * gmr::skeleton_size(demo.motion);
  if (!(max_error <= tolerance)) {
    std::fprintf(stderr, "fast FK differs from the reference by %g (tolerance %g)\n", max_error, tolerance);
    return 1;
  }
  std::printf("fast FK matches the reference (max error %.2g)\n", max_error);
  return 0;
}
