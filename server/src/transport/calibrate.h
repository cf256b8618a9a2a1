// The send budget measured on this machine (--send-budget auto): how much a
// frame sent to a client costs here, against the reference machine where the
// default budget was measured.
#pragma once

#include <cstddef>

#include "gmr/core/error.h"

namespace gmr::server {

struct SendCalibration {
  double ns_per_send = 0;  // CPU per frame-sized TCP write, its loopback delivery and its read: the slowest CPU's
  double fastest_ns_per_send = 0;  // the fastest CPU's, which the budget is scaled by
  double budget = 0;               // frames/s: the reference budget scaled by how fast this machine sends
  std::size_t cpus = 0;            // CPUs measured
  std::size_t sends = 0;           // writes timed
  double seconds = 0;              // wall time the calibration took
};

// On the reference 2-core machine (docs/performance.md, "TCP without an
// allocation per frame"), one I/O thread holds 102,000 frames/s of own TCP
// streams at 120 Hz with p99 <= 2 ms (850 subscribers: p99 0.61 / 0.68 ms;
// 700 0.07 / 0.12 ms; 1,000 2.5-9.2 ms in three runs, all frames delivered),
// and this calibration measured 3,550 ns per send there (the fastest CPU's fastest round:
// 3,504-3,893 ns in eleven starts of twelve, 4,733 once; the slowest CPU's
// ranged 3,566-5,869 ns from one start to the next, which made the budget
// it gave vary by a third).
inline constexpr double kReferenceBudget = 102000;
inline constexpr double kReferenceNsPerSend = 3550;

// On each CPU the process may use (at most 16), a thread pinned there times
// `rounds` rounds of `sends_per_round` writes of `bytes` bytes over a
// loopback TCP connection (TCP_NODELAY), each read back at once by the same
// thread, by its CPU clock: a measure of how fast this machine's kernel moves
// a frame that does not depend on what else runs (a second thread reading
// would make it: wake-ups and a shared socket cost as much as the send).
// Each CPU's fastest round is its figure (interference only slows a round
// down); the fastest CPU's figure scales the budget: kReferenceBudget times
// kReferenceNsPerSend / that, stable from one start to the next. Takes about
// 0.05 s per CPU. An error when no loopback connection can be made.
Result<SendCalibration> calibrate_send_budget(std::size_t bytes = 480, std::size_t sends_per_round = 4000,
                                              int rounds = 5);

}  // namespace gmr::server
