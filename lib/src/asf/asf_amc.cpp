#include "gmr/io/asf_amc.h"

namespace gmr {

// Temporary until the ASF/AMC reader lands.
Result<Motion> read_asf_amc(const std::filesystem::path& asf, const std::filesystem::path& amc, Warnings*) {
  return Error{amc.string(), 0, 0, "ASF/AMC reading is not implemented yet"};
}

}  // namespace gmr
