// File commands: info, convert, positions.
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "cli_util.h"
#include "cmd_retarget.h"
#include "cmd_markers.h"
#include "cmd_ops.h"
#include "commands.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "gmr/io/motion_file.h"
#include "gmr/io/positions_csv.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/motion/motion.h"
#include "gmr/ops/convert.h"
#include "gmr/view/viewpoint.h"

namespace gmr::cli {
namespace {

std::string format_seconds(double s) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", s);
  return buf;
}

// ---- gmr info

struct InfoOptions {
  std::string file;
  std::string asf;
  std::string model;  // marker input: a skeleton model to fit (built-in name or file)
  double fps = 0.0;   // .amc input: frames per second (0: 120)
  bool humanoid = false;
};

void run_info(const InfoOptions& o) {
  if (is_marker_file(o.file)) return run_marker_info(o.file, o.model);  // .c3d, .trc: cmd_markers.cpp
  if (!o.model.empty()) throw CommandError("--model applies to marker files (.c3d, .trc), not to " + o.file);
  Warnings warnings;
  const Motion m = load(o.file, o.asf, o.fps, warnings);
  const Skeleton& sk = m.skeleton;
  std::string roots;
  int leaves = 0;
  for (int r : sk.roots()) roots += (roots.empty() ? "" : ", ") + sk.joint(r).name;
  for (int j = 0; j < static_cast<int>(sk.size()); ++j) leaves += sk.children(j).empty() ? 1 : 0;

  std::string out;
  out += "file:        " + o.file + "\n";
  out += std::string("convention:  ") +
         (m.convention == Convention::kPostRotation ? "post-rotation (BVH: a joint's rotation moves its children)"
                                                    : "pre-rotation (GMR: a joint's rotation moves the joint)") +
         "\n";
  out += "joints:      " + std::to_string(sk.size()) + " (" + std::to_string(leaves) + " leaves)\n";
  out += "roots:       " + std::to_string(sk.roots().size()) + " (" + roots + ")\n";
  out += "channels:    " + std::to_string(sk.channel_count()) + " per frame\n";
  out += "frames:      " + std::to_string(m.frame_count) + "\n";
  if (m.frame_time > 0) {
    out += "frame time:  " + format_seconds(m.frame_time) + " s (" + format_seconds(1.0 / m.frame_time) + " fps)\n";
    out += "duration:    " + format_seconds(m.duration()) + " s\n";
  } else {
    out += "frame time:  unknown (0 in the file)\n";
    out += "duration:    unknown\n";
  }
  out += "hierarchy:\n";
  // Depth-first, children indented under their parent.
  std::vector<int> stack(sk.roots().rbegin(), sk.roots().rend());
  while (!stack.empty()) {
    const int j = stack.back();
    stack.pop_back();
    const Joint& joint = sk.joint(j);
    out += "  " + tree_indent(sk.depth(j)) + joint.name;
    if (!joint.channels.empty()) {
      out += "  [";
      for (std::size_t c = 0; c < joint.channels.size(); ++c) {
        if (c) out += ' ';
        out += channel_name(joint.channels[c]);
      }
      out += "]";
    }
    if (joint.soft_parent != kNoParent) out += "  (soft link to " + sk.joint(joint.soft_parent).name + ")";
    out += "\n";
    const auto ch = sk.children(j);
    for (auto it = ch.rbegin(); it != ch.rend(); ++it) stack.push_back(*it);
  }
  std::fwrite(out.data(), 1, out.size(), stdout);
  if (o.humanoid) print_humanoid(sk);
  print_warnings(warnings);
}

// ---- gmr convert

struct ConvertOptions {
  std::string in;
  std::string out;
  std::string asf;
  double fps = 0.0;                // .amc input: frames per second (0: 120)
  bool force = false;              // .amc output: replace an .asf beside it that holds another skeleton
  bool single_root = false;        // .bvh output: a forest as one ROOT
  std::string model;               // marker input: the skeleton model (built-in name or file)
  std::string roots;               // marker input with a model: the essential joints, A,B
  double calibrate_seconds = 0.0;  // marker input with a model: solve frame by frame (0: the whole take)
};

void run_convert(const ConvertOptions& o) {
  if (is_marker_file(o.in)) {
    return run_marker_convert(o.in, o.out, o.model, o.roots, o.calibrate_seconds);  // cmd_markers.cpp
  }
  if (!o.model.empty() || !o.roots.empty() || o.calibrate_seconds != 0) {
    throw CommandError("--model and --roots apply to marker files (.c3d, .trc), not to " + o.in);
  }
  Warnings warnings;
  const Motion m = load(o.in, o.asf, o.fps, warnings);
  LoadOptions save;
  save.replace_asf = o.force;
  save.bvh_single_root = o.single_root;
  check(save_motion(m, o.out, save));
  print_warnings(warnings);
}

// ---- gmr positions

// Options of `gmr positions`: the frames, and the view (--roots,
// --strip-dummies, --relative-to; registered by add_positions_transform_options()).
struct PositionsOptions {
  std::string file;
  std::string asf;
  double fps = 0.0;  // .amc input: frames per second (0: 120)
  std::string frames = ":";
  std::string orientations;  // "", "quat" or "matrix"
  bool local_transforms = false;
  std::string model;  // marker input: the skeleton model (built-in name or file)
  ViewOptions view;   // --roots, --strip-dummies, --relative-to (cmd_ops.cpp)
};

void add_positions_transform_options(CLI::App& cmd, PositionsOptions& o) { add_view_options(cmd, o.view); }

// The motion as loaded -> the motion whose positions are printed. Whatever it
// does, positions must stay those of the file unless an option says otherwise.
Motion transform_for_positions(Motion m, const PositionsOptions& o) {
  (void)o;
  return m;
}

void run_positions(const PositionsOptions& given) {
  PositionsOptions o = given;
  const FrameRange requested = parse_frame_range(o.frames);
  Warnings warnings;
  double file_metres_per_unit = 0.0;
  Motion loaded;
  if (is_marker_file(o.file)) {  // markers through a skeleton model: cmd_markers.cpp
    loaded = marker_motion(o.file, o.model, file_metres_per_unit, warnings);
  } else {
    if (!o.model.empty()) throw CommandError("--model applies to marker files (.c3d, .trc), not to " + o.file);
    LoadOptions lo;
    lo.asf = o.asf;
    file_metres_per_unit = take(motion_metres_per_unit(o.file, lo));
    loaded = load(o.file, o.asf, o.fps, warnings);
  }
  // The file's own unit, as gmr-server takes it, unless given.
  warn_if_unit_unknown(o.view, file_metres_per_unit);
  if (o.view.metres_per_unit == 0.0) o.view.metres_per_unit = file_metres_per_unit;
  const Motion m = transform_for_positions(std::move(loaded), o);
  const OutputBasis basis = o.view.basis();
  if (o.view.any() || o.local_transforms) {
    write_view_positions(m, o.view, requested, std::cout, pose_columns(o.orientations, o.local_transforms));
    std::cout.flush();
    if (!std::cout) throw CommandError("cannot write the positions to standard output");
    print_warnings(warnings);
    return;
  }
  const FrameRange r = clamp_frame_range(requested, m.frame_count);
  constexpr std::size_t kChunk = 1024;  // chunks keep memory flat for long motions
  if (!o.orientations.empty()) {
    // Orientations are GMR's (docs/gmr-format.md): W_j is the frame of the
    // bone from j's parent to j, whatever the file's convention.
    const OrientationColumns columns =
        o.orientations == "matrix" ? OrientationColumns::kMatrix : OrientationColumns::kQuaternion;
    const Motion pre = take(to_pre_rotation(m));
    const std::size_t joints = pre.skeleton.size();
    write_poses_csv_header(std::cout, columns);
    std::vector<Eigen::Vector3d> p;
    std::vector<Eigen::Matrix3d> w;
    for (std::size_t f = r.begin; f < r.end; f += kChunk) {
      const std::size_t e = std::min(r.end, f + kChunk);
      p.resize((e - f) * joints);
      w.resize((e - f) * joints);
      for (std::size_t k = f; k < e; ++k) {
        view_frame(pre, -1, k, std::span(p).subspan((k - f) * joints, joints),
                   std::span(w).subspan((k - f) * joints, joints), basis);
      }
      write_poses_csv_rows(std::cout, pre.skeleton, p, w, f, columns);
    }
  } else {
    write_positions_csv_header(std::cout);
    for (std::size_t f = r.begin; f < r.end; f += kChunk) {
      const std::size_t e = std::min(r.end, f + kChunk);
      auto p = compute_positions(m, f, e);
      for (auto& x : p) x = basis.position(x);
      write_positions_csv_rows(std::cout, m.skeleton, p, f);
    }
  }
  std::cout.flush();
  if (!std::cout) throw CommandError("cannot write the positions to standard output");
  print_warnings(warnings);
}

}  // namespace

void add_file_commands(CLI::App& app) {
  {
    auto o = std::make_shared<InfoOptions>();
    CLI::App* cmd = app.add_subcommand("info", "Show a motion file's joints, roots, channels, frames and duration");
    cmd->add_option("FILE", o->file, "Motion file (.bvh, .gmr, .amc) or marker file (.c3d, .trc)")->required();
    cmd->add_option("--asf", o->asf, "Skeleton for an .amc file (default: the single .asf beside it)");
    add_fps_option(*cmd, o->fps);
    cmd->add_option("--model", o->model,
                    "Marker file: fit this skeleton model (built-in name such as cmu41, or a model file) and report "
                    "the residuals");
    cmd->add_flag("--humanoid", o->humanoid,
                  "Also print the humanoid roles the built-in namings find (for gmr retarget; docs/retarget.md)");
    cmd->callback([o] { run_info(*o); });
  }
  {
    auto o = std::make_shared<ConvertOptions>();
    CLI::App* cmd = app.add_subcommand("convert",
                                       "Convert between motion formats by extension (.bvh, .gmr, .gmrb, .amc+.asf; "
                                       "markers .c3d/.trc to .trc, or to a motion with --model); atomic write");
    cmd->add_option("IN", o->in, "Input motion file (.bvh, .gmr, .amc) or marker file (.c3d, .trc)")->required();
    cmd->add_option("OUT", o->out, "Output motion file (.bvh, .gmr, .gmrb, .amc); .trc for marker input")->required();
    cmd->add_option("--asf", o->asf, "Skeleton for an .amc input (default: the single .asf beside it)");
    add_fps_option(*cmd, o->fps);
    cmd->add_flag("--force", o->force, "For .amc output: replace an existing .asf that holds another skeleton");
    add_single_root_flag(*cmd, o->single_root);
    cmd->add_option("--model", o->model,
                    "Marker input: the skeleton model that turns markers into a motion (built-in name such as cmu41, "
                    "or a model file; docs/markers.md)");
    cmd->add_option("--roots", o->roots, "Marker input with --model: the essential joints, the motion's roots (A,B)");
    cmd->add_option("--calibrate-seconds", o->calibrate_seconds,
                    "Marker input with --model: solve each frame alone, as a live source is, on a calibration of the "
                    "take's first S seconds (docs/markers.md, \"Frame by frame\"); 0: the whole take at once");
    cmd->callback([o] { run_convert(*o); });
  }
  {
    auto o = std::make_shared<PositionsOptions>();
    CLI::App* cmd = app.add_subcommand(
        "positions", "Print every joint's world position as CSV: frame,joint,x,y,z (frames from 0, file order)");
    cmd->add_option("FILE", o->file, "Motion file (.bvh, .gmr, .amc), or marker file (.c3d, .trc) with --model")
        ->required();
    cmd->add_option("--frames", o->frames, "Half-open frame range A:B (frames A to B-1; ':' = all)");
    cmd->add_option("--model", o->model,
                    "Marker file: the skeleton model that gives the joints (built-in name such as cmu41, or a model "
                    "file; docs/markers.md)");
    cmd->add_option("--asf", o->asf, "Skeleton for an .amc file (default: the single .asf beside it)");
    add_fps_option(*cmd, o->fps);
    add_positions_transform_options(*cmd, *o);
    add_pose_options(*cmd, o->orientations, o->local_transforms);
    cmd->callback([o] { run_positions(*o); });
  }
}

}  // namespace gmr::cli
