#include "streams/frame_encoder.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <vector>

#include "gmr/fast/compiled_motion.h"
#include "gmr/fast/fast_fk.h"
#include "gmr/view/engine_pose.h"
#include "gmr/view/viewpoint.h"
#include "gmr/wire/frames.h"
#include "streams/fk_blocks.h"

namespace gmr::server {

namespace {

// What encode_frame() computes a frame in: used only inside one call, so
// every stream of a thread shares one set (and it stays in cache) instead of
// each stream keeping its own (the FK workspace alone is ~23 KB for a CMU
// skeleton). Grows to the largest content shown.
struct Scratch {
  std::vector<Eigen::Vector3d> all_positions;  // double path
  std::vector<Eigen::Matrix3d> all_orientations;
  std::vector<double> positions_f64, orientations_f64;
  std::vector<float> workspace;  // float path
  std::vector<float> positions_f32, orientations_f32;
  std::vector<Eigen::Quaterniond> local_rotations;  // local transforms
  std::vector<Eigen::Vector3d> local_translations;
  std::vector<double> local_rotations_f64, local_translations_f64;
  std::vector<float> local_rotations_f32, local_translations_f32;
};

Scratch& scratch() {
  static thread_local Scratch s;
  return s;
}

// For streams made without the server's FkBlocks (each frame computed alone).
FkBlocks& unkept_blocks() {
  static thread_local FkBlocks none(0);
  return none;
}

// The local transforms of `joints` from every joint's pose in w.all_*, as
// float64 and float32 values.
void encode_locals(const Skeleton& skeleton, std::span<const int> own_frames, std::span<const int> joints, Scratch& w) {
  w.local_rotations.resize(joints.size());
  w.local_translations.resize(joints.size());
  engine_locals(skeleton, own_frames, w.all_positions, w.all_orientations, joints, w.local_rotations,
                w.local_translations);
  w.local_rotations_f64.clear();
  w.local_translations_f64.clear();
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const auto& q = w.local_rotations[i];
    const auto& t = w.local_translations[i];
    w.local_rotations_f64.insert(w.local_rotations_f64.end(), {q.x(), q.y(), q.z(), q.w()});
    w.local_translations_f64.insert(w.local_translations_f64.end(), {t.x(), t.y(), t.z()});
  }
  w.local_rotations_f32.assign(w.local_rotations_f64.begin(), w.local_rotations_f64.end());
  w.local_translations_f32.assign(w.local_translations_f64.begin(), w.local_translations_f64.end());
}

}  // namespace

std::shared_ptr<const std::string> encode_frame(const ViewContent& content, const Stream::Settings& settings,
                                                std::span<const int> own_frames, std::uint64_t frame,
                                                std::uint64_t index, std::uint64_t sequence, StreamCounters& counters) {
  Scratch& w = scratch();
  const Motion& m = *content.motion;
  const std::size_t n = m.skeleton.size();
  const int viewer = content.relative_to;
  const std::vector<int>& joints = settings.joints;
  wire::FrameContent c;
  c.skeleton_version = content.skeleton_version;
  c.frame_index = index;
  c.motion_time = static_cast<double>(index) * m.frame_time;
  c.sequence = sequence;
  c.float64 = settings.float64;

  // The float path: FK in float, the viewpoint and quaternions computed from
  // its output and rounded once, straight into what the encoder sends.
  const fast::CompiledMotion* cm = !settings.float64 && content.compiled ? content.compiled->get() : nullptr;
  bool done = false;
  if (cm != nullptr && cm->joint_count() == n && frame < cm->frame_count() && viewer < static_cast<int>(n)) {
    // The viewer's orientation is needed even when the client wants none.
    const bool orient = settings.orientations || viewer >= 0 || settings.local_transforms;
    w.workspace.resize(std::max(w.workspace.size(), content.compiled->workspace_floats()));
    FkBlocks& blocks = counters.fk_blocks != nullptr ? *counters.fk_blocks : unkept_blocks();
    if (const auto pose = blocks.frame(content.compiled, frame, orient, w.workspace)) {
      const std::span<const float> fk_positions = pose->positions, fk_orientations = pose->orientations;
      w.positions_f32.resize(joints.size() * 3);
      w.orientations_f32.resize(settings.orientations ? joints.size() * 4 : 0);
      view_frame_float(fk_positions, fk_orientations, viewer, joints, w.positions_f32, w.orientations_f32,
                       settings.basis);
      c.positions = w.positions_f32;
      c.orientations = w.orientations_f32;
      if (settings.local_transforms) {
        // Every joint's pose in double (a joint's parent and own frame may
        // not be among those sent), then the locals of those sent.
        w.all_positions.resize(n);
        w.all_orientations.resize(n);
        const Viewpoint from =
            viewer < 0 ? Viewpoint()
                       : Viewpoint::of_joint(fk_positions, fk_orientations, static_cast<std::size_t>(viewer));
        for (std::size_t j = 0; j < n; ++j) {
          const float* p = fk_positions.data() + 3 * j;
          const float* o = fk_orientations.data() + 9 * j;
          Eigen::Matrix3d r;
          r << o[0], o[1], o[2], o[3], o[4], o[5], o[6], o[7], o[8];
          w.all_positions[j] = settings.basis.position(from.position(Eigen::Vector3d(p[0], p[1], p[2])));
          w.all_orientations[j] = settings.basis.orientation(from.orientation(r));
        }
        encode_locals(m.skeleton, own_frames, joints, w);
        c.local_rotations = w.local_rotations_f32;
        c.local_translations = w.local_translations_f32;
      }
      ++counters.frames_computed_float;
      done = true;
    }
  }
  if (!done) {
    w.all_positions.resize(n);
    w.all_orientations.resize(settings.orientations || viewer >= 0 || settings.local_transforms ? n : 0);
    view_frame(m, viewer, frame, w.all_positions, w.all_orientations, settings.basis);
    if (settings.local_transforms) encode_locals(m.skeleton, own_frames, joints, w);
    w.positions_f64.clear();
    w.orientations_f64.clear();
    for (int j : joints) {
      const auto& p = w.all_positions[static_cast<std::size_t>(j)];
      w.positions_f64.insert(w.positions_f64.end(), {p.x(), p.y(), p.z()});
      if (settings.orientations) {
        const Eigen::Quaterniond q(w.all_orientations[static_cast<std::size_t>(j)]);
        w.orientations_f64.insert(w.orientations_f64.end(), {q.x(), q.y(), q.z(), q.w()});
      }
    }
    if (settings.float64) {
      c.positions_f64 = w.positions_f64;
      c.orientations_f64 = w.orientations_f64;
      if (settings.local_transforms) {
        c.local_rotations_f64 = w.local_rotations_f64;
        c.local_translations_f64 = w.local_translations_f64;
      }
    } else {  // a float32 stream whose motion did not compile: rounded once here
      w.positions_f32.assign(w.positions_f64.begin(), w.positions_f64.end());
      w.orientations_f32.assign(w.orientations_f64.begin(), w.orientations_f64.end());
      c.positions = w.positions_f32;
      c.orientations = w.orientations_f32;
      if (settings.local_transforms) {
        c.local_rotations = w.local_rotations_f32;
        c.local_translations = w.local_translations_f32;
      }
    }
  }
  ++counters.frames_computed;
  c.server_send_time_ns = now_ns();
  auto body = std::make_shared<const std::string>(wire::encode_frame_body(c));
  ++counters.frames_encoded;
  return body;
}

}  // namespace gmr::server
