// Helpers shared by the ASF/AMC tests.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "gmr/acclaim/convert.h"
#include "gmr/acclaim/kinematics.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "test_data.h"

namespace gmr::test {

// A small skeleton in CMU style: root -> hip (dof rx ry rz, axis) -> knee (rx)
// and root -> back (rz rx, no axis). Angles in degrees.
inline const char* kSmallAsf = R"(:version 1.10
:name small
:units
  mass 1.0
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name hip
     direction 0.34202 -0.939693 0
     length 7.5
     axis 0 0 20 XYZ
     dof rx ry rz
     limits (-160.0 20.0)
            (-70.0 70.0)
            (-60.0 70.0)
  end
  begin
     id 2
     name knee
     direction 0.34202 -0.939693 0
     length 7.0
     axis 0 0 20 XYZ
     dof rx
     limits (-10.0 170.0)
  end
  begin
     id 3
     name back
     direction 0 1 0
     length 2
     axis 0 0 0 XYZ
     dof rz rx
  end
:hierarchy
  begin
    root hip back
    hip knee
  end
)";

inline const char* kSmallAmc = R"(:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 10 20 30
hip 5 -10 15
knee 40
back 7 -3
2
root 1.5 2.5 3.5 -10 5 0
hip 25 10 -15
knee 80
back -7 3
)";

// Parses or fails the test.
inline AsfSkeleton must_parse_asf(const std::string& text, Warnings* w = nullptr) {
  auto r = parse_asf(text, "test.asf", w);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().to_string());
  return r.ok() ? std::move(*r) : AsfSkeleton{};
}
inline AmcMotion must_parse_amc(const std::string& text, const AsfSkeleton& s, Warnings* w = nullptr) {
  auto r = parse_amc(text, "test.amc", s, w);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().to_string());
  return r.ok() ? std::move(*r) : AmcMotion{};
}

// `make test-sanitize` runs these tests in a Debug + ASan build, where Eigen is
// ~50x slower: there the corpus-wide tests keep the first kSanitizerFrames
// frames of each take (and walk prefixes in bigger steps). The Release run
// (`make test-unit`) checks every frame.
#if defined(GMR_SANITIZED)
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif
inline constexpr std::size_t kSanitizerFrames = 150;

// Frames a corpus-wide test looks at.
inline std::size_t frames_to_check(std::size_t frames) {
  return kSanitized ? std::min(frames, kSanitizerFrames) : frames;
}

// Keeps the first frames_to_check() frames of m.
inline void limit_frames(AmcMotion& m, const AsfSkeleton& s) {
  const std::size_t n = frames_to_check(m.frame_count);
  m.frame_count = n;
  m.values.resize(n * static_cast<std::size_t>(s.value_count()));
  if (m.frame_numbers.size() > n) m.frame_numbers.resize(n);
}

// Every (asf, amc) pair of the corpus: each .amc with the one .asf of its folder.
inline std::vector<std::pair<std::filesystem::path, std::filesystem::path>> acclaim_pairs() {
  std::vector<std::pair<std::filesystem::path, std::filesystem::path>> out;
  for (const auto& amc : data_files("asfamc", ".amc")) {
    std::filesystem::path asf;
    for (const auto& e : std::filesystem::directory_iterator(amc.parent_path())) {
      if (e.path().extension() == ".asf") asf = e.path();
    }
    out.emplace_back(asf, amc);
  }
  return out;
}

// Positions from the Acclaim model and from a GMR motion converted from it
// agree (GMR joint j = bone j).
inline double acclaim_gmr_max_error(const AsfSkeleton& s, const AmcMotion& m, const Motion& g) {
  const auto a = acclaim_positions(s, m);
  const auto b = compute_positions(g);
  const auto d = compare_positions(a, b, s.bones.size());
  return a.size() == b.size() ? d.max_error : 1e300;
}

}  // namespace gmr::test
