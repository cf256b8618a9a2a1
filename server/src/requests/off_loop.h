// Work a request starts that is too long for the control loop (a long view
// edit, a marker calibration): computed on the edit pool, its outcome handed
// back to the control loop. Nothing thrown leaves the pool's thread: running
// out of memory, or any other exception, becomes the outcome's error.
#pragma once

#include <exception>
#include <new>
#include <string>
#include <string_view>
#include <utility>

#include "gmr/core/error.h"
#include "transport/net.h"

namespace gmr::server {

// `work()` (a Result<T>) on `pool`, then `done(outcome)` on `io`. `doing`
// names the work in the errors ("the edit": "the edit failed: ..."). What
// `work` holds is let go on the pool's thread, what `done` holds on `io`'s
// (so control-loop state belongs in `done`; `work` may point into it).
template <class T, class Work, class Done>
void run_off_loop(net::thread_pool& pool, net::io_context& io, std::string_view doing, Work work, Done done) {
  net::post(pool, [&io, doing = std::string(doing), work = std::move(work), done = std::move(done)]() mutable {
    Result<T> outcome = [&]() -> Result<T> {
      try {
        return work();
      } catch (const std::bad_alloc&) {
        return make_error(ErrorKind::kResourceExhausted, "the server ran out of memory computing " + doing);
      } catch (const std::exception& e) {
        return make_error(ErrorKind::kFailedPrecondition, doing + " failed: " + e.what());
      }
    }();
    net::post(io, [done = std::move(done), outcome = std::move(outcome)]() mutable { done(std::move(outcome)); });
  });
}

}  // namespace gmr::server
