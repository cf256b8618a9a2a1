// .gmrb reader: any bytes give a motion or an error at a byte offset; what it
// gives can be viewed and written, and the written bytes read back.
#include "fuzz_util.h"
#include "gmr/io/gmrb.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  auto m = gmr::parse_gmrb(bytes, "fuzz.gmrb");
  if (!m.ok()) return 0;
  gmr::fuzz::exercise(*m);
  if (auto out = gmr::format_gmrb(*m); out.ok()) {
    gmr::fuzz::require(gmr::parse_gmrb(*out, "again.gmrb").ok(), "format_gmrb output reads back");
  }
  return 0;
}
