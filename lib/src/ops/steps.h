// Private: the steps the GMR operations are built from (paper 4.1, with the
// primes restored in docs/gmr-math.md), shared by shift_root, split_tree,
// join_tree and set_roots.
#pragma once

#include <string>
#include <vector>

#include "gmr/core/error.h"
#include "gmr/motion/motion.h"
#include "gmr/ops/join_tree.h"
#include "work.h"

namespace gmr::detail {

std::string quoted(const std::string& name);
// The motion is pre-rotation and valid; `op` names the operation in the error.
Status check_pre(const Motion& m, const char* op);
// `j` is a joint of m (ErrorKind::kNotFound otherwise).
Status check_joint(const Motion& m, int j, const char* op);
// Paper 4.1.1: swaps root j0 with its child j1 in `w` (every frame).
void swap_root(Work& w, int j0, int j1);
// Splits every joint of `joints` (non-roots) in one pass.
Result<Motion> split_many(const Motion& motion, const std::vector<int>& joints);
// Joins every root of `roots` under its soft parent in one pass; checks each
// join and that they form no cycle.
Result<Motion> join_many(const Motion& motion, const std::vector<int>& roots, std::vector<JoinReport>* out_reports);

}  // namespace gmr::detail
