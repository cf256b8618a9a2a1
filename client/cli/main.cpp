// gmr: one command, git-style subcommands. Files: info, convert, positions,
// markers, roots, shift, split, join, strip-dummies, demo; a server: ls,
// skeleton, query, stream. (The performance experiments are bench/harness: gmr-bench.)
#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>
#include <new>
#include <string>
#include <string_view>

#include "cli_util.h"
#include "gmr/core/file_util.h"
#include "commands.h"

namespace {

// An error message's lines, each escaped (its line breaks are the message's own).
std::string shown_lines(std::string_view text) {
  std::string out;
  for (std::size_t start = 0;;) {
    const std::size_t end = text.find('\n', start);
    out += gmr::cli::shown(text.substr(start, end == std::string_view::npos ? end : end - start));
    if (end == std::string_view::npos) break;
    out += '\n';
    start = end + 1;
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"gmr: General Motion Representation tools"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "gmr 0.1.0");
  // An interrupted `gmr convert` leaves no temporary behind.
  gmr::remove_temporaries_on_signals();
  gmr::cli::add_file_commands(app);
  gmr::cli::add_ops_commands(app);
  gmr::cli::add_net_commands(app);
  gmr::cli::add_demo_commands(app);
  gmr::cli::add_marker_commands(app);
  gmr::cli::add_retarget_commands(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Usage errors: CLI11 prints help or the problem; --help exits 0.
    return app.exit(e);
  } catch (const gmr::cli::CommandError& e) {
    // An error may quote what a server or a file said: escaped, line by line.
    std::fprintf(stderr, "gmr: %s\n", shown_lines(e.what()).c_str());
    return 1;
  } catch (const std::bad_alloc&) {
    // Readers bound what a file may declare (docs/gmr-format.md, "Limits"),
    // so this is a real shortage, not a file's say-so.
    std::fprintf(stderr, "gmr: %s: out of memory (the input needs more than this process may use)\n",
                 app.get_subcommands().empty() ? "gmr" : app.get_subcommands().front()->get_name().c_str());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "gmr: %s\n", shown_lines(e.what()).c_str());
    return 1;
  }
  return 0;
}
