#include "commands.h"

namespace gmr::cli {

void add_net_commands(CLI::App& app) { (void)app; }

}  // namespace gmr::cli
