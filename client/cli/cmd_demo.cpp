// gmr demo OUTDIR: writes the built-in demo library, one file per motion.
#include <filesystem>
#include <iostream>

#include "cli_util.h"
#include "commands.h"
#include "gmr/demo/demo_library.h"
#include "gmr/io/motion_file.h"

namespace gmr::cli {

void add_demo_commands(CLI::App& app) {
  auto* cmd = app.add_subcommand("demo", "Write the built-in demo motions (procedural, human skeleton) to a folder");
  static std::string out_dir;
  static std::string format = "gmr";
  cmd->add_option("OUTDIR", out_dir, "Folder to write into (created if missing)")->required();
  cmd->add_option("--format", format, "File format: gmr or bvh")->check(CLI::IsMember({"gmr", "bvh"}));
  cmd->callback([] {
    std::error_code ec;
    std::filesystem::create_directories(out_dir, ec);
    if (ec) throw CommandError(out_dir + ": cannot create folder: " + ec.message());
    for (const NamedMotion& m : demo_library()) {
      const auto path = std::filesystem::path(out_dir) / (m.name + "." + format);
      check(save_motion(m.motion, path));
      std::cout << path.string() << ": " << m.motion.frame_count << " frames, " << m.motion.skeleton.size()
                << " joints\n";
    }
  });
}

}  // namespace gmr::cli
