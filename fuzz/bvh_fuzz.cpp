// BVH reader: any bytes give a motion or a located error; a motion it gives
// can be viewed, converted and written, and what is written reads back.
#include "fuzz_util.h"
#include "gmr/io/bvh.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  gmr::Warnings warnings;
  auto m = gmr::parse_bvh(text, "fuzz.bvh", &warnings);
  if (!m.ok()) return 0;
  gmr::fuzz::exercise(*m);
  if (auto out = gmr::format_bvh(*m); out.ok()) {
    gmr::fuzz::require(gmr::parse_bvh(*out, "again.bvh").ok(), "format_bvh output reads back");
  }
  return 0;
}
