// The measured send budget, measured again while the server runs: a start
// whose calibration something slowed (on a shared machine whole seconds can
// be slow) is corrected within a minute, and the budget settles on what the
// machine has shown it can do.
#pragma once

#include <chrono>
#include <functional>
#include <memory>

#include "gmr/core/error.h"
#include "transport/net.h"

namespace gmr::server {

class BudgetRefresh {
 public:
  // `measure` gives a budget in frames/s (run on `worker`, never on `io`);
  // `raise` takes a higher one, on `io`. Measured `times` times, `first`
  // after start() and each wait twice the one before (1, 2, 4 ... 32 s by
  // default: the last about a minute after start). A measurement only ever
  // raises the budget: interference slows a calibration down, never up.
  BudgetRefresh(net::io_context& io, net::thread_pool& worker, std::function<Result<double>()> measure,
                std::function<void(double)> raise, int times = 6,
                std::chrono::milliseconds first = std::chrono::seconds(1));
  ~BudgetRefresh();
  BudgetRefresh(const BudgetRefresh&) = delete;
  BudgetRefresh& operator=(const BudgetRefresh&) = delete;

  // From `budget` (the start's measurement); on io's thread.
  void start(double budget);
  // No measurement after this one (a measurement running finishes and is
  // dropped); on io's thread.
  void stop();

  double budget() const { return budget_; }   // on io's thread
  int measured() const { return measured_; }  // measurements done, on io's thread

 private:
  void arm();

  net::io_context& io_;
  net::thread_pool& worker_;
  std::function<Result<double>()> measure_;
  std::function<void(double)> raise_;
  int times_;
  std::chrono::milliseconds wait_;
  net::steady_timer timer_;
  double budget_ = 0;
  int measured_ = 0;
  // Shared with a measurement in flight: false once stopped or gone (the
  // io_context and the worker outlive this object).
  std::shared_ptr<bool> running_ = std::make_shared<bool>(false);
};

}  // namespace gmr::server
