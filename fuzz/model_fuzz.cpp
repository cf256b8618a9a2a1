// Marker skeleton models: any text gives a model or a located error; a model
// that parses is solved on markers made up for it (every marker it names,
// moving), which gives a motion or an error, never a crash.
#include <cmath>

#include "fuzz_util.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/marker_solve.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  auto model = gmr::parse_marker_model(text, "fuzz.model");
  if (!model.ok()) return 0;
  gmr::MarkerTrajectories m;
  m.names = model->marker_names();
  if (m.names.size() > 200) return 0;
  m.units = "mm";
  m.frame_rate = 100;
  m.frame_count = 16;
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    for (std::size_t i = 0; i < m.names.size(); ++i) {
      const double a = 0.3 * static_cast<double>(f) + static_cast<double>(i);
      m.positions.insert(m.positions.end(),
                         {100 * std::cos(a) + static_cast<double>(i * 37 % 101),
                          100 * std::sin(a) + static_cast<double>(f), static_cast<double>(i * 13 % 29) * 10});
    }
  }
  auto solved = gmr::solve_markers(m, *model);
  if (!solved.ok()) return 0;
  gmr::fuzz::require(solved->motion.frame_count == m.frame_count, "the motion has every marker frame");
  gmr::fuzz::exercise(solved->motion);
  return 0;
}
