// gmr retarget: a motion on another humanoid rig (gmr/retarget/retarget.h,
// docs/retarget.md); gmr info RIG --humanoid prints what a rig's map finds.
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <map>
#include <memory>
#include <string>

#include "cli_util.h"
#include "cmd_retarget.h"
#include "commands.h"
#include "gmr/core/file_util.h"
#include "gmr/io/motion_file.h"
#include "gmr/retarget/retarget.h"

namespace gmr::cli {
namespace {

// A --map file: a JSON object of role -> joint name.
std::map<std::string, std::string> read_map(const std::string& path) {
  const std::string text = take(read_file(path));
  const auto json = nlohmann::json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (json.is_discarded() || !json.is_object()) {
    throw CommandError(path + ": not a JSON object of role -> joint name (docs/retarget.md, \"Maps\")");
  }
  std::map<std::string, std::string> m;
  for (const auto& [role, joint] : json.items()) {
    if (!joint.is_string()) throw CommandError(path + ": role '" + role + "' must name a joint as a string");
    m[role] = joint.get<std::string>();
  }
  return m;
}

struct RetargetCommand {
  std::string source, out, target, asf, map, source_map;
  double fps = 0.0;
  bool single_root = false;
  bool keep_contacts = false;
};

void run_retarget(const RetargetCommand& o) {
  Warnings warnings;
  const Motion source = load(o.source, o.asf, o.fps, warnings);
  Warnings rig_warnings;
  const Motion rig = load(o.target, "", 0.0, rig_warnings);
  std::map<std::string, std::string> target_map, source_map;
  RetargetOptions options;
  if (!o.map.empty()) {
    target_map = read_map(o.map);
    options.target_map = &target_map;
  }
  if (!o.source_map.empty()) {
    source_map = read_map(o.source_map);
    options.source_map = &source_map;
  }
  RetargetPlan plan;
  Motion out = take(retarget(source, rig, options, &plan));
  ContactReport contacts;
  if (o.keep_contacts) out = take(keep_contacts(out, plan, {}, &contacts));
  LoadOptions save;
  save.bvh_single_root = o.single_root;
  take(save_motion(out, o.out, save));
  std::fprintf(stderr,
               "retargeted %zu frames: %s (%s naming, measured in its %s) onto %s (%s naming, its %s), %zu joints "
               "driven, root path scaled by %.6g\n",
               out.frame_count, o.source.c_str(), plan.source.naming.c_str(), plan.source_reference.c_str(),
               o.target.c_str(), plan.target.naming.c_str(), plan.target_reference.c_str(), plan.driven.size(),
               plan.scale);
  if (o.keep_contacts) {
    std::fprintf(stderr,
                 "feet kept on the floor: %zu contacts (%zu foot-frames); the farthest a resting ankle slid: %.6g "
                 "before, %.6g after (rig units)%s\n",
                 contacts.contacts, contacts.frames_pinned, contacts.slide_before, contacts.slide_after,
                 contacts.out_of_reach > 0
                     ? (", " + std::to_string(contacts.out_of_reach) + " foot-frames out of the leg's reach").c_str()
                     : "");
  }
  print_warnings(warnings);
}

}  // namespace

void print_humanoid(const Skeleton& skeleton) {
  const HumanoidMap m = take(map_humanoid(skeleton));
  std::printf("humanoid:    %s naming\n", m.naming.c_str());
  for (std::size_t r = 0; r < kRoleCount; ++r) {
    const Role role = static_cast<Role>(r);
    const std::string joint = m.has(role) ? skeleton.joint(m[role]).name : std::string("-");
    std::printf("  %-16s %s%s\n", std::string(role_name(role)).c_str(), joint.c_str(),
                m.has(role) || !role_required(role) ? "" : "  (required)");
  }
  std::size_t unmapped = 0;
  for (int j = 0; j < static_cast<int>(skeleton.size()); ++j) {
    if (std::find(m.joint.begin(), m.joint.end(), j) == m.joint.end()) ++unmapped;
  }
  std::printf("  %zu other joints follow their parents (twist, helper, finger and face bones)\n", unmapped);
}

void add_retarget_commands(CLI::App& app) {
  auto o = std::make_shared<RetargetCommand>();
  CLI::App* cmd = app.add_subcommand(
      "retarget",
      "Put a motion on another humanoid rig: OUT has the rig's skeleton (names, hierarchy, bone lengths) "
      "and the source's frames (docs/retarget.md); atomic write");
  cmd->add_option("SOURCE", o->source, "The motion (.bvh, .gmr, .gmrb, .amc)")->required();
  cmd->add_option("OUT", o->out, "Output file by extension (.bvh, .gmr, .gmrb)")->required();
  cmd->add_option("--target", o->target, "The rig: a file whose skeleton is the target (.bvh, .gmr, .gmrb)")
      ->required();
  cmd->add_option("--asf", o->asf, "Skeleton for an .amc source (default: the single .asf beside it)");
  add_fps_option(*cmd, o->fps);
  cmd->add_option("--map", o->map, "The rig's roles as JSON {\"hips\": \"Pelvis\", ...} (default: built-in namings)");
  cmd->add_option("--source-map", o->source_map, "The source's roles, as --map (default: built-in namings)");
  add_single_root_flag(*cmd, o->single_root);
  cmd->add_flag("--keep-contacts", o->keep_contacts,
                "Keep resting feet where they rest: an IK on each leg pins the ankle while it is on the floor "
                "(docs/retarget.md, \"Foot contacts\")");
  cmd->callback([o] { run_retarget(*o); });
}

}  // namespace gmr::cli
