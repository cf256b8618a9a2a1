#include "commands.h"

namespace gmr::cli {

void add_ops_commands(CLI::App& app) { (void)app; }

}  // namespace gmr::cli
