// Where the benchmarks find the shared corpus, and the motions they share.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "gmr/ops/convert.h"
#include "gmr/io/bvh.h"
#include "gmr/ops/join_tree.h"
#include "gmr/ops/set_roots.h"
#include "gmr/ops/shift_root.h"
#include "gmr/ops/split_tree.h"
#include "gmr/ops/strip_dummies.h"

namespace gmr::bench {

// $GMR_DATA_DIR, else <source>/../shared/data.
inline std::filesystem::path data_dir() {
  if (const char* env = std::getenv("GMR_DATA_DIR")) return env;
  return std::filesystem::path(GMR_SOURCE_DIR) / ".." / "shared" / "data";
}

// The main file of the issue: CMU 01_01 (31 joints + 7 end sites, 2752 frames).
inline std::filesystem::path main_bvh() { return data_dir() / "bvh" / "cmu" / "01_01.bvh"; }

[[noreturn]] inline void die(const std::string& what) {
  std::fprintf(stderr, "gmr bench: %s\n", what.c_str());
  std::exit(1);
}

inline Motion load_main_bvh() {
  auto m = read_bvh(main_bvh());
  if (!m) die(m.error().to_string());
  return std::move(*m);
}

// The GMR form of `bvh` with `k` roots: its own roots plus k - roots random
// joints (seeded); k >= joints gives every joint a root.
inline Motion with_roots(const Motion& bvh, std::size_t k, unsigned seed) {
  auto gmr = to_pre_rotation(bvh);
  if (!gmr) die(gmr.error().to_string());
  std::vector<int> roots = gmr->skeleton.roots();
  std::vector<int> rest;
  for (int j = 0; j < static_cast<int>(gmr->skeleton.size()); ++j) {
    if (!gmr->skeleton.is_root(j)) rest.push_back(j);
  }
  std::mt19937 rng(seed);
  std::shuffle(rest.begin(), rest.end(), rng);
  for (int j : rest) {
    if (roots.size() >= k) break;
    roots.push_back(j);
  }
  auto moved = set_roots(*gmr, roots);
  if (!moved) die(moved.error().to_string());
  return std::move(*moved);
}

}  // namespace gmr::bench
