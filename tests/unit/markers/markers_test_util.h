// Helpers of the marker tests.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "test_data.h"

namespace gmr::test {

// A corpus marker file (path relative to ../shared/data), loaded by
// extension; a failed load is a test failure and gives empty data.
inline MarkerTrajectories load_marker_file(const std::string& rel, Warnings* w = nullptr) {
  auto r = load_markers(data_file(rel), w);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.error().to_string());
  return r.ok() ? std::move(r).value() : MarkerTrajectories{};
}

}  // namespace gmr::test
