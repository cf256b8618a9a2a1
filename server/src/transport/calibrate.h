// The send budget measured on this machine (--send-budget auto): how much a
// frame sent to a client costs here, against the reference machine where the
// default budget was measured.
#pragma once

#include <cstddef>

#include "gmr/core/error.h"

namespace gmr::server {

struct SendCalibration {
  double ns_per_send = 0;  // CPU per frame-sized TCP write, its loopback delivery and its read: the slowest CPU's
  double fastest_ns_per_send = 0;  // the fastest CPU's
  double budget = 0;               // frames/s: the reference budget scaled by how fast this machine sends
  std::size_t cpus = 0;            // CPUs measured
  std::size_t sends = 0;           // writes timed
  double seconds = 0;              // wall time the calibration took
};

// On the reference 2-core machine (docs/performance.md, "Server"), one I/O
// thread held 30,000 frames/s at 120 Hz with p99 <= 2 ms, and this
// calibration measured 6,000 ns per send there (5,860-6,770 on either CPU,
// idle or with both busy; for a few minutes one CPU took 9,000-9,330, the
// host's doing, which is why the slowest CPU counts).
inline constexpr double kReferenceBudget = 30000;
inline constexpr double kReferenceNsPerSend = 6000;

// On each CPU the process may use (at most 16), a thread pinned there times
// `rounds` rounds of `sends_per_round` writes of `bytes` bytes over a
// loopback TCP connection (TCP_NODELAY), each read back at once by the same
// thread, by its CPU clock: a measure of how fast this machine's kernel moves
// a frame that does not depend on what else runs (a second thread reading
// would make it: wake-ups and a shared socket cost as much as the send).
// The slowest CPU's median round counts, since the I/O thread may run on any:
// kReferenceBudget is scaled by kReferenceNsPerSend / that. Takes about 0.05 s
// per CPU. An error when no loopback connection can be made.
Result<SendCalibration> calibrate_send_budget(std::size_t bytes = 480, std::size_t sends_per_round = 4000,
                                              int rounds = 5);

}  // namespace gmr::server
