// The send budget measured on this machine (--send-budget auto): how much a
// frame sent to a client costs here, against the reference machine where the
// default budget was measured.
#pragma once

#include <chrono>
#include <cstddef>

#include "gmr/core/error.h"

namespace gmr::server {

struct SendCalibration {
  double ns_per_send = 0;          // CPU per frame-sized TCP write and its loopback delivery: the slowest CPU's
  double fastest_ns_per_send = 0;  // the fastest CPU's, which the budget is scaled by
  double budget = 0;               // frames/s: the reference budget scaled by how fast this machine sends
  std::size_t cpus = 0;            // CPUs measured
  std::size_t sends = 0;           // writes timed
  double seconds = 0;              // wall time the calibration took
};

// On the reference 2-core machine (docs/performance.md, "Admission against
// the grid", 2026-11-28), one I/O thread sends about 120,000 frames/s of own
// TCP streams at saturation (1,000 subscribers at 120 Hz: 98.5-99.9% of
// their frames delivered; 3,000: 124,760 frames/s), and this calibration
// measured 3,350 ns per send there (3,344-3,357 ns in five starts of six,
// 3,631 once; in a later session 3,330-3,390 ns, spread as below). The
// budget is 0.9 of what it sends: 108,000 frames/s (900 subscribers), which
// admits every load of that day's grid that got every frame (1,000
// subscribers of each other kind) and refuses part of every load past
// saturation. The calibration before it (one connection, each frame read
// back at once) measured 6,811-8,393 ns that day against 3,550 on an earlier
// one, while the server's CPU per own TCP frame at 1,000-3,000 subscribers
// was 4-17% above the earlier day's: its budget had halved (43,000-54,000).
inline constexpr double kReferenceBudget = 108000;
inline constexpr double kReferenceNsPerSend = 3350;

// A frame-sized message and a fan-out's width: the start's calibration and
// measure_send_budget() use the same.
inline constexpr std::size_t kCalibrationBytes = 480;
inline constexpr std::size_t kCalibrationConnections = 64;

// On each CPU the process may use (at most 16), a thread pinned there in
// turn times `passes` passes, each a write of `bytes` bytes to every one of
// `connections` loopback TCP connections (TCP_NODELAY; the readers drained
// after each pass, untimed), by its CPU clock: what the kernel's send path
// costs this machine for a fan-out, which is most of what a subscriber's
// frame costs the server. Each CPU's fastest pass is its figure
// (interference only slows a pass down); the fastest CPU's figure scales the
// budget: kReferenceBudget times kReferenceNsPerSend / that. The passes run
// in `rounds` rounds `gap` apart, each round visiting every CPU (about 0.5 s
// in all, 0.6 s on 2 CPUs): whatever else keeps a CPU busy as the server
// starts (another process's sockets closing, a previous run's server
// exiting) rarely lasts through every round. Back to back (0.05 s a CPU),
// 13 starts of 33 came out 8-26% slow; spread, 0 to 8 of 33 in four runs
// (the machine's slow spells last seconds), which BudgetRefresh corrects
// (docs/performance.md, "Admission against the grid"). An error when no
// loopback connection can be made.
Result<SendCalibration> calibrate_send_budget(std::size_t bytes = kCalibrationBytes,
                                              std::size_t connections = kCalibrationConnections, int passes = 100,
                                              int rounds = 10,
                                              std::chrono::milliseconds gap = std::chrono::milliseconds(50));

// A quick measurement while the server runs (BudgetRefresh): 20 passes on
// each CPU, two at a time 1 ms apart (holding a CPU about 0.5 ms at a time,
// 30 ms in all); the budget it gives (107,274-107,904 frames/s in five runs
// on an idle reference-kind machine, against 107,055-108,701 at start).
Result<double> measure_send_budget();

}  // namespace gmr::server
