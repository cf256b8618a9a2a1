// LiveDirectory: what the live side (the NATS relay's sources from other
// replicas) needs of the server's catalogue of motions, without knowing it.
// The Catalog implements it.
#pragma once

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "live/live_source.h"

namespace gmr::server {

class LiveDirectory {
 public:
  virtual ~LiveDirectory() = default;
  // Whether a library motion or a live source (ended or not) has this name.
  virtual bool serves(std::string_view name) const = 0;
  // A new live source under `name` (not served yet), listed from now on.
  virtual std::shared_ptr<LiveSource> add_live(const std::string& name, Skeleton skeleton, double frame_time,
                                               double metres_per_unit) = 0;
  // Unlists `source` (when it is still the one listed under its name).
  virtual void remove_live(const std::shared_ptr<LiveSource>& source) = 0;
  // The sources published on this replica (no origin), for re-announcing.
  virtual std::vector<std::shared_ptr<LiveSource>> local_sources() const = 0;
  // What became of a frame pushed to a live source.
  enum class FrameFate { kAccepted, kRefused, kOverRate };
  virtual void count_live_frame(FrameFate fate) = 0;
};

}  // namespace gmr::server
