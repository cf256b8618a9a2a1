// gmr retarget, and the humanoid report of gmr info --humanoid (cmd_retarget.cpp).
#pragma once

#include "gmr/skeleton/skeleton.h"

namespace gmr::cli {

// Every role and the joint the built-in namings give it; fails (CommandError)
// naming the required roles a rig lacks.
void print_humanoid(const Skeleton& skeleton);

}  // namespace gmr::cli
