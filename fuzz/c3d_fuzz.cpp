// C3D reader: any bytes give marker trajectories or an error at a byte
// offset; what it gives is written as TRC and read back.
#include "fuzz_util.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/trc.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  gmr::Warnings warnings;
  auto d = gmr::parse_c3d(bytes, "fuzz.c3d", &warnings);
  if (!d.ok()) return 0;
  gmr::fuzz::require(d->positions.size() == d->frame_count * d->names.size() * 3, "positions hold every frame");
  if (auto trc = gmr::format_trc(*d, "fuzz.trc"); trc.ok()) (void)gmr::parse_trc(*trc, "again.trc");
  return 0;
}
