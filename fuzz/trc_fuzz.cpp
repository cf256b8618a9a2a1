// TRC reader: any bytes give marker trajectories or a located error; what
// it gives is written and read back.
#include "fuzz_util.h"
#include "gmr/markers/trc.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  gmr::Warnings warnings;
  auto d = gmr::parse_trc(text, "fuzz.trc", &warnings);
  if (!d.ok()) return 0;
  gmr::fuzz::require(d->positions.size() == d->frame_count * d->names.size() * 3, "positions hold every frame");
  if (auto out = gmr::format_trc(*d, "fuzz.trc"); out.ok()) {
    gmr::fuzz::require(gmr::parse_trc(*out, "again.trc").ok(), "format_trc output reads back");
  }
  return 0;
}
