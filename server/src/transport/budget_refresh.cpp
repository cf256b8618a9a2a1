#include "transport/budget_refresh.h"

#include <spdlog/spdlog.h>

#include <utility>

namespace gmr::server {

BudgetRefresh::BudgetRefresh(net::io_context& io, net::thread_pool& worker, std::function<Result<double>()> measure,
                             std::function<void(double)> raise, int times, std::chrono::milliseconds first)
    : io_(io),
      worker_(worker),
      measure_(std::move(measure)),
      raise_(std::move(raise)),
      times_(times),
      wait_(first),
      timer_(io) {}

BudgetRefresh::~BudgetRefresh() { *running_ = false; }

void BudgetRefresh::start(double budget) {
  budget_ = budget;
  *running_ = true;
  arm();
}

void BudgetRefresh::stop() {
  *running_ = false;
  timer_.cancel();
}

void BudgetRefresh::arm() {
  if (!*running_ || measured_ >= times_) return;
  timer_.expires_after(wait_);
  wait_ *= 2;
  timer_.async_wait([this, running = running_](const boost::system::error_code& ec) {
    if (ec || !*running) return;
    // The measurement blocks its thread for a few milliseconds: the worker's,
    // not the control loop's. Its outcome comes back to io; `running` says
    // whether this object is still there to take it.
    net::post(worker_, [this, &io = io_, measure = measure_, running] {
      auto measured = measure();
      net::post(io, [this, running, measured = std::move(measured)] {
        if (!*running) return;
        ++measured_;
        if (!measured.ok()) {
          spdlog::warn("send budget: measuring again failed: {}", measured.error().to_string());
        } else if (*measured > budget_) {
          spdlog::info("send budget raised from {:.0f} to {:.0f} frames/s (measured again {} of {})", budget_,
                       *measured, measured_, times_);
          budget_ = *measured;
          raise_(budget_);
        }
        arm();
      });
    });
  });
}

}  // namespace gmr::server
