// Private: marker name helpers shared by the C3D and TRC readers.
#pragma once

#include <string>
#include <vector>

namespace gmr::detail {

// Renames repeated names in place: the second "A" becomes "A_2", the third
// "A_3" (skipping suffixes already taken). True when anything was renamed.
bool make_names_unique(std::vector<std::string>& names);

}  // namespace gmr::detail
