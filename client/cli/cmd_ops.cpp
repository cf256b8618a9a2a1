// GMR operation commands: roots, shift, split, join, strip-dummies,
// constant-rotations; and the view options of `gmr positions`.
//
// Every command reads .bvh / .gmr / .amc (converted to pre-rotation first),
// applies one operation to all frames, and saves by the output's extension
// (atomic). Unknown joints and impossible operations exit 1 with one line.
#include "cmd_ops.h"

#include <cctype>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "commands.h"
#include "gmr/ops/convert.h"
#include "gmr/io/motion_file.h"
#include "gmr/io/positions_csv.h"
#include "gmr/ops/join_tree.h"
#include "gmr/ops/set_roots.h"
#include "gmr/ops/shift_root.h"
#include "gmr/ops/split_tree.h"
#include "gmr/ops/strip_dummies.h"
#include "gmr/view/engine_pose.h"
#include "gmr/view/view.h"
#include "gmr/view/viewpoint.h"

namespace gmr::cli {
namespace {

struct OpOptions {
  std::string file;
  std::string out;
  std::string asf;
  double fps = 0.0;          // .amc input: frames per second (0: 120)
  std::string joints;        // --set / --to / --at / --root
  bool single_root = false;  // .bvh output: a forest as one ROOT
};

// Loads FILE as a pre-rotation motion.
Motion load_pre(const OpOptions& o, Warnings& warnings) {
  LoadOptions options;
  options.asf = o.asf;
  options.amc_fps = o.fps;
  Motion m = take(load_motion(o.file, options, &warnings));
  return take(to_pre_rotation(m));
}

void save(const Motion& m, const OpOptions& o) {
  LoadOptions options;
  options.bvh_single_root = o.single_root;
  check(save_motion(m, o.out, options));
}

void run_roots(const OpOptions& o) {
  Warnings w;
  const Motion m = load_pre(o, w);
  const std::vector<std::string> names = split_list(o.joints);
  const std::vector<int> roots = take(find_joints(m.skeleton, names));
  save(take(set_roots(m, roots)), o);
  print_warnings(w);
}

void run_shift(const OpOptions& o) {
  Warnings w;
  const Motion m = load_pre(o, w);
  const std::vector<int> j = take(find_joints(m.skeleton, std::vector<std::string>{o.joints}));
  save(take(shift_root(m, j[0])), o);
  print_warnings(w);
}

void run_split(const OpOptions& o) {
  Warnings w;
  const Motion m = load_pre(o, w);
  const std::vector<int> j = take(find_joints(m.skeleton, std::vector<std::string>{o.joints}));
  save(take(split_tree(m, j[0])), o);
  print_warnings(w);
}

void run_join(const OpOptions& o) {
  Warnings w;
  const Motion m = load_pre(o, w);
  const std::vector<int> j = take(find_joints(m.skeleton, std::vector<std::string>{o.joints}));
  JoinReport report;
  save(take(join_tree(m, j[0], &report)), o);
  if (report.translation_channels) {
    std::printf("joined %s: its offset varies over frames (spread %.9g), kept as translation channels\n",
                o.joints.c_str(), report.offset_spread);
  } else {
    std::printf("joined %s: static offset (spread %.3g)\n", o.joints.c_str(), report.offset_spread);
  }
  print_warnings(w);
}

void run_strip(const OpOptions& o) {
  Warnings w;
  const Motion m = load_pre(o, w);
  std::vector<RemovedJoint> removed;
  const Motion stripped = take(strip_dummies(m, &removed));
  save(stripped, o);
  for (const RemovedJoint& r : removed)
    std::printf("removed %s (zero-length, merged into %s)\n", r.name.c_str(), r.merged_into.c_str());
  if (removed.empty()) std::printf("no zero-length joints to remove\n");
  // BVH cannot let siblings rotate independently without zero-length joints:
  // say so when the writer had to insert some back.
  if (lower_extension(o.out) == ".bvh") {
    const auto post = to_post_rotation(stripped);
    if (post && post->skeleton.size() > stripped.skeleton.size()) {
      std::fprintf(stderr,
                   "gmr: note: BVH needs zero-length joints where siblings rotate independently: %zu were "
                   "inserted (*_gmr_pre); write .gmr to keep them out\n",
                   post->skeleton.size() - stripped.skeleton.size());
    }
  }
  print_warnings(w);
}

void run_constant(const OpOptions& o, double tolerance) {
  Warnings w;
  LoadOptions options;
  options.asf = o.asf;
  options.amc_fps = o.fps;
  const Motion m = take(load_motion(o.file, options, &w));
  for (const std::string& name : constant_rotation_joints(m, tolerance)) std::printf("%s\n", name.c_str());
  print_warnings(w);
}

CLI::App* add_op(CLI::App& app, const char* name, const char* help, const std::shared_ptr<OpOptions>& o) {
  CLI::App* cmd = app.add_subcommand(name, help);
  cmd->add_option("FILE", o->file, "Motion file (.bvh, .gmr, .amc)")->required();
  cmd->add_option("-o,--output", o->out, "Output file (.gmr, .bvh); written atomically")->required();
  cmd->add_option("--asf", o->asf, "Skeleton for an .amc file (default: the single .asf beside it)");
  add_fps_option(*cmd, o->fps);
  add_single_root_flag(*cmd, o->single_root);
  return cmd;
}

}  // namespace

Conventions ViewOptions::engine() const {
  Conventions c;
  c.preset = preset_named(conventions).value_or(ConventionPreset::kNative);
  c.source_metres_per_unit = metres_per_unit;
  return c;
}

OutputBasis ViewOptions::basis() const { return take(output_basis(engine())); }

void warn_if_unit_unknown(const ViewOptions& o, double motion_metres_per_unit) {
  if (o.conventions == "native" || o.metres_per_unit != 0.0 || motion_metres_per_unit != 0.0) return;
  std::fprintf(stderr,
               "gmr: warning: the motion's unit is unknown (BVH and .gmr files declare none): --conventions %s "
               "turns its axes but leaves its numbers in the motion's own units; give --metres-per-unit (0.01 for "
               "centimetres, 0.0254 for inches), or declare it in X.units or folder.units beside the file, for "
               "positions in %s's unit\n",
               o.conventions.c_str(), o.conventions.c_str());
}

void add_view_options(CLI::App& cmd, ViewOptions& o) {
  cmd.add_option("--roots", o.roots, "Joints to make the roots, A,B,C (all frames; positions do not change)");
  cmd.add_flag("--strip-dummies", o.strip_dummies, "Remove zero-length joints (e.g. CMU LHipJoint) before printing");
  cmd.add_option("--relative-to", o.relative_to,
                 "Give coordinates in this joint's frame (its GMR bone frame, see docs/operations.md)");
  cmd.add_option("--conventions", o.conventions,
                 "An engine's axes, handedness and unit: native (as in the file), unreal, unity, blender, godot")
      ->check(CLI::IsMember({"native", "unreal", "unity", "blender", "godot"}))
      ->capture_default_str();
  cmd.add_option("--metres-per-unit", o.metres_per_unit,
                 "The motion's unit in metres (0.0254: inches), for --conventions to change units (default: the "
                 "file's own, which an .asf declares, else a units sidecar's (X.units or folder.units beside a "
                 "BVH or .gmr); else unknown, positions keep the motion's units)")
      ->check(CLI::PositiveNumber);
}

PoseColumns pose_columns(const std::string& orientations, bool local_transforms) {
  PoseColumns c;
  if (orientations == "quat") c.orientations = OrientationColumns::kQuaternion;
  if (orientations == "matrix") c.orientations = OrientationColumns::kMatrix;
  c.local_transforms = local_transforms;
  return c;
}

void add_pose_options(CLI::App& cmd, std::string& orientations, bool& local_transforms) {
  cmd.add_option("--orientations", orientations,
                 "Also print each joint's orientation (its GMR bone frame, in the view's coordinates and "
                 "conventions, with any view option): quat (qw,qx,qy,qz) or matrix (r00..r22, row by row)")
      ->check(CLI::IsMember({"quat", "matrix"}));
  cmd.add_flag("--local-transforms", local_transforms,
               "Also print each joint's local transform as an engine bone takes it (rotation lqw,lqx,lqy,lqz and "
               "translation ltx,lty,ltz relative to its parent's frame, in the view's conventions; "
               "docs/protocol.md, \"Local transforms and rest pose\")");
}

void write_view_positions(const Motion& motion, const ViewOptions& o, FrameRange requested, std::ostream& out,
                          const PoseColumns& columns) {
  ViewSpec spec;
  if (!o.roots.empty()) spec.roots = split_list(o.roots);
  spec.strip_dummies = o.strip_dummies;
  spec.relative_to = o.relative_to;
  const MotionView view = take(apply_view(motion, spec));
  const FrameRange r = clamp_frame_range(requested, view.motion.frame_count);
  const Skeleton names = view_names(view);
  const OutputBasis basis = o.basis();
  constexpr std::size_t kChunk = 1024;  // keeps memory flat for long motions
  write_pose_header(out, columns);
  if (!columns.orientations && !columns.local_transforms) {
    for (std::size_t f = r.begin; f < r.end; f += kChunk) {
      const std::size_t e = std::min(r.end, f + kChunk);
      std::vector<Eigen::Vector3d> p = view_positions(view, f, e);
      for (auto& x : p) x = basis.position(x);
      write_positions_csv_rows(out, names, p, f);
    }
    return;
  }
  // Positions, orientations and locals of the view's frame (view_frame and
  // engine_locals, as the server computes them), rows in view.order.
  const std::size_t joints = view.motion.skeleton.size();
  const std::vector<int> sources = columns.local_transforms ? own_frame_sources(view.motion) : std::vector<int>{};
  std::vector<Eigen::Vector3d> p(joints), rows_p, lt(view.order.size()), rows_t;
  std::vector<Eigen::Matrix3d> w(joints), rows_w;
  std::vector<Eigen::Quaterniond> lq(view.order.size()), rows_q;
  for (std::size_t f = r.begin; f < r.end; f += kChunk) {
    const std::size_t e = std::min(r.end, f + kChunk);
    rows_p.clear();
    rows_w.clear();
    rows_q.clear();
    rows_t.clear();
    for (std::size_t k = f; k < e; ++k) {
      view_frame(view.motion, view.viewer, k, p, w, basis);
      if (columns.local_transforms) engine_locals(view.motion.skeleton, sources, p, w, view.order, lq, lt);
      for (std::size_t i = 0; i < view.order.size(); ++i) {
        const auto j = static_cast<std::size_t>(view.order[i]);
        rows_p.push_back(p[j]);
        rows_w.push_back(w[j]);
        if (columns.local_transforms) {
          rows_q.push_back(lq[i]);
          rows_t.push_back(lt[i]);
        }
      }
    }
    write_pose_rows(out, names, {rows_p, rows_w, rows_q, rows_t}, f, columns);
  }
}

void add_ops_commands(CLI::App& app) {
  {
    auto o = std::make_shared<OpOptions>();
    CLI::App* cmd = add_op(app, "roots", "Make exactly the given joints the roots (any set, all frames)", o);
    cmd->add_option("--set", o->joints, "Joints to be roots, A,B,C")->required();
    cmd->callback([o] { run_roots(*o); });
  }
  {
    auto o = std::make_shared<OpOptions>();
    CLI::App* cmd = add_op(app, "shift", "Move the root of a joint's tree to that joint", o);
    cmd->add_option("--to", o->joints, "The joint that becomes the root")->required();
    cmd->callback([o] { run_shift(*o); });
  }
  {
    auto o = std::make_shared<OpOptions>();
    CLI::App* cmd = add_op(app, "split", "Make a joint a root with a soft link to its parent", o);
    cmd->add_option("--at", o->joints, "The joint that becomes a root")->required();
    cmd->callback([o] { run_split(*o); });
  }
  {
    auto o = std::make_shared<OpOptions>();
    CLI::App* cmd = add_op(app, "join", "Put a split root back under its soft-link parent", o);
    cmd->add_option("--root", o->joints, "The root to join")->required();
    cmd->callback([o] { run_join(*o); });
  }
  {
    auto o = std::make_shared<OpOptions>();
    CLI::App* cmd = add_op(app, "strip-dummies", "Remove zero-length joints exactly and print what was removed", o);
    cmd->callback([o] { run_strip(*o); });
  }
  {
    auto o = std::make_shared<OpOptions>();
    auto tolerance = std::make_shared<double>(1e-9);
    CLI::App* cmd = app.add_subcommand("constant-rotations", "List joints whose rotation never changes");
    cmd->add_option("FILE", o->file, "Motion file (.bvh, .gmr, .amc)")->required();
    cmd->add_option("--asf", o->asf, "Skeleton for an .amc file (default: the single .asf beside it)");
    add_fps_option(*cmd, o->fps);
    cmd->add_option("--tolerance", *tolerance, "Largest change from frame 0, in degrees (default 1e-9)");
    cmd->callback([o, tolerance] { run_constant(*o, *tolerance); });
  }
}

}  // namespace gmr::cli
