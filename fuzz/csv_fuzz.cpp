// Positions CSV reader (what `gmr publish x.csv` plays): any bytes give a
// table or a located error; a table it gives is written by the CSV writer
// and read back to the same joints, positions and orientations.
#include <sstream>

#include "fuzz_util.h"
#include "gmr/io/positions_csv.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  auto t = gmr::parse_positions_csv(text, "fuzz.csv");
  if (!t.ok()) {
    gmr::fuzz::require(!t.error().message.empty(), "an error says what");
    return 0;
  }
  using gmr::fuzz::require;
  require(!t->joints.empty() && t->frames > 0, "a table has rows");
  require(t->positions.size() == t->frames * t->joints.size(), "positions hold every frame and joint");
  require(t->orientations.empty() || t->orientations.size() == t->positions.size(), "orientations hold every row");

  // Written back (joints as roots of a skeleton, the writer's only use of
  // it is their names) and read again.
  std::vector<gmr::Joint> joints(t->joints.size());
  for (std::size_t j = 0; j < joints.size(); ++j) joints[j].name = t->joints[j];
  auto skeleton = gmr::Skeleton::create(std::move(joints));
  if (!skeleton.ok()) return 0;  // names the reader takes but a skeleton does not (not the reader's concern)
  std::vector<Eigen::Matrix3d> rotations;
  for (const auto& q : t->orientations) rotations.push_back(q.toRotationMatrix());
  std::ostringstream out;
  if (rotations.empty()) {
    gmr::write_positions_csv_header(out);
  } else {
    gmr::write_poses_csv_header(out, gmr::OrientationColumns::kQuaternion);
  }
  gmr::write_poses_csv_rows(out, *skeleton, t->positions, rotations, t->first_frame,
                            gmr::OrientationColumns::kQuaternion);
  auto again = gmr::parse_positions_csv(out.str(), "again.csv");
  require(again.ok(), "what the writer writes reads back");
  require(again->joints == t->joints && again->first_frame == t->first_frame && again->frames == t->frames,
          "the same joints and frames");
  require(again->positions == t->positions, "the same positions, bit for bit");
  require(again->orientations.size() == t->orientations.size(), "the same orientations");
  for (std::size_t i = 0; i < t->orientations.size(); ++i) {
    require(again->orientations[i].angularDistance(t->orientations[i]) < 1e-6, "the same orientations");
  }
  return 0;
}
