#include "commands.h"

namespace gmr::cli {

void add_demo_commands(CLI::App& app) { (void)app; }

}  // namespace gmr::cli
