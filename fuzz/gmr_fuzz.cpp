// GMR text reader: any bytes give a motion or a located error; what it gives
// can be viewed and written, and the written text reads back.
#include "fuzz_util.h"
#include "gmr/io/gmr_file.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  gmr::Warnings warnings;
  auto m = gmr::parse_gmr(text, "fuzz.gmr", &warnings);
  if (!m.ok()) return 0;
  gmr::fuzz::exercise(*m);
  if (auto out = gmr::format_gmr(*m); out.ok()) {
    gmr::fuzz::require(gmr::parse_gmr(*out, "again.gmr").ok(), "format_gmr output reads back");
  }
  return 0;
}
