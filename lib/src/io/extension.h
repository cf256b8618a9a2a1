// Private: file-extension helpers shared by load_motion() and save_motion().
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "gmr/core/error.h"

namespace gmr::detail {

// Lower-case extension with its dot (".bvh"), or "" when there is none.
std::string lower_extension(const std::filesystem::path& path);
// "cannot <verb> '.xyz' files: expected .bvh, .gmr, .amc or .gmrb", naming the path.
Error unknown_extension(const std::filesystem::path& path, std::string_view verb);

}  // namespace gmr::detail
