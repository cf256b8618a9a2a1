#include "requests/rig.h"

#include <cmath>
#include <string>

#include "gmr/wire/convert.h"

namespace gmr::server {

std::variant<std::shared_ptr<const Motion>, Refusal> check_rig(const pb::Retarget& r, const ServerConfig& cfg) {
  if (static_cast<std::uint64_t>(r.target().joints_size()) > cfg.max_live_joints) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "retarget: the rig has " +
                                                          std::to_string(r.target().joints_size()) +
                                                          " joints, above the server's limit of " +
                                                          std::to_string(cfg.max_live_joints) + " (--max-live-joints)"};
  }
  if (const double u = r.target().metres_per_unit(); !std::isfinite(u) || u < 0.0) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST,
                   "retarget: the rig's unit (metres_per_unit) must be a positive length, or 0 for the motion's"};
  }
  auto skeleton = wire::from_proto(r.target());
  if (!skeleton.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, "retarget: the rig: " + skeleton.error().message};
  auto rig = std::make_shared<Motion>();
  rig->skeleton = std::move(skeleton).value();
  rig->convention = Convention::kPostRotation;
  rig->frame_time = 1.0;
  if (r.reference_size() > 0) {
    if (static_cast<std::size_t>(r.reference_size()) != rig->stride()) {
      return Refusal{pb::ERROR_CODE_BAD_REQUEST, "retarget: the reference pose has " +
                                                     std::to_string(r.reference_size()) + " values for the rig's " +
                                                     std::to_string(rig->stride()) + " channels"};
    }
    rig->frame_count = 1;
    rig->values.assign(r.reference().begin(), r.reference().end());
  }
  if (auto s = rig->validate(); !s.ok()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, "retarget: " + s.error().message};
  return std::shared_ptr<const Motion>(std::move(rig));
}

}  // namespace gmr::server
