// Subcommands of the `gmr` command. Each group adds its own to the app.
#pragma once

#include <CLI/CLI.hpp>

namespace gmr::cli {

void add_file_commands(CLI::App& app);      // info, convert, positions   (cmd_files.cpp)
void add_ops_commands(CLI::App& app);       // roots, shift, split, join, strip-dummies (cmd_ops.cpp)
void add_net_commands(CLI::App& app);       // ls, skeleton, query, stream (cmd_net.cpp)
void add_demo_commands(CLI::App& app);      // demo: write the built-in library (cmd_demo.cpp)
void add_marker_commands(CLI::App& app);    // markers: CSV of a .c3d/.trc   (cmd_markers.cpp)
void add_retarget_commands(CLI::App& app);  // retarget: onto another rig (cmd_retarget.cpp)

// --fps of the commands that read motions: the frame rate of an .amc input,
// which the file does not hold (default 120, the CMU captures').
inline void add_fps_option(CLI::App& cmd, double& fps) {
  cmd.add_option("--fps", fps, "Frames per second of an .amc input (AMC files do not say; default 120)")
      ->check(CLI::PositiveNumber);
}

// --single-root of the commands that write motions: a forest saved as .bvh
// gets one ROOT (gmr::BvhExportOptions::single_root), for readers that take
// only one tree.
inline void add_single_root_flag(CLI::App& cmd, bool& flag) {
  cmd.add_flag("--single-root", flag,
               ".bvh output: write a forest as one ROOT (a gmr_world joint at the origin) for readers that take one");
}

}  // namespace gmr::cli
