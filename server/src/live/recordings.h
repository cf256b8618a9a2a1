// Recordings: live sources' recorded frames written to files off the control
// loop (save_motion is atomic: a file appears whole or not at all). The
// server waits for the writes still running when it stops.
#pragma once

#include <future>
#include <memory>
#include <string>
#include <vector>

#include "gmr/motion/motion.h"

namespace gmr::server {

class Recordings {
 public:
  ~Recordings() { wait(); }
  // Writes `motion`, live source `name`'s recording, to `file` (logged;
  // `truncated`: the recording was cut at its limit).
  void write(std::shared_ptr<const Motion> motion, std::string file, std::string name, bool truncated);
  // Waits for every write under way.
  void wait();

 private:
  std::vector<std::future<void>> running_;
};

}  // namespace gmr::server
