#include "live/recordings.h"

#include <spdlog/spdlog.h>

#include <chrono>

#include "gmr/io/motion_file.h"
#include "transport/net.h"

namespace gmr::server {

void Recordings::write(std::shared_ptr<const Motion> motion, std::string file, std::string name, bool truncated) {
  std::erase_if(running_,
                [](std::future<void>& f) { return f.wait_for(std::chrono::seconds(0)) == std::future_status::ready; });
  running_.push_back(std::async(
      std::launch::async, [motion = std::move(motion), file = std::move(file), name = std::move(name), truncated] {
        if (Status s = save_motion(*motion, file); !s.ok()) {
          spdlog::error("live {}: recording not written: {}", printable(name, 200), s.error().to_string());
          return;
        }
        spdlog::info("live {}: recorded {} frames to {}{}", printable(name, 200), motion->frame_count, file,
                     truncated ? " (cut at --max-record-bytes)" : "");
      }));
}

void Recordings::wait() {
  for (auto& r : running_) r.wait();
  running_.clear();
}

}  // namespace gmr::server
