// ASF reader: any bytes give a skeleton or a located error; a skeleton it
// gives is written, and the writing read again.
#include "fuzz_util.h"
#include "gmr/acclaim/asf.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  gmr::Warnings warnings;
  auto s = gmr::parse_asf(text, "fuzz.asf", &warnings);
  if (!s.ok()) return 0;
  (void)gmr::parse_asf(gmr::format_asf(*s), "again.asf");
  return 0;
}
