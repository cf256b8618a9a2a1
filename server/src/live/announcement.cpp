#include "live/announcement.h"

#include <fmt/format.h>

#include <cmath>
#include <string>
#include <string_view>

#include "gmr/wire/convert.h"
#include "gmr/core/names.h"
#include "transport/net.h"
#include "streams/stream.h"

namespace gmr::server {

namespace {

constexpr std::size_t kMaxLiveNameBytes = 200;

}  // namespace

std::variant<Skeleton, Refusal> check_announcement(const pb::Publish& r, const ServerConfig& cfg) {
  if (r.name().empty()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, "a live source needs a name"};
  if (const std::string why = name_problem(r.name(), kMaxLiveNameBytes); !why.empty()) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "source name " + printable(r.name(), 64) + ": " + why};
  }
  if (static_cast<std::size_t>(r.skeleton().joints_size()) > cfg.max_live_joints) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "a skeleton of " + std::to_string(r.skeleton().joints_size()) +
                                                          " joints; live sources have at most " +
                                                          std::to_string(cfg.max_live_joints)};
  }
  if (r.skeleton().joints_size() == 0) return Refusal{pb::ERROR_CODE_BAD_REQUEST, "the skeleton has no joints"};
  // Joint names reach every subscriber's screen: the same rule as source names.
  for (int j = 0; j < r.skeleton().joints_size(); ++j) {
    const std::string& name = r.skeleton().joints(j).name();
    if (const std::string why = name_problem(name, kMaxLiveNameBytes); !why.empty()) {
      return Refusal{pb::ERROR_CODE_BAD_REQUEST,
                     "joint " + std::to_string(j) + " name " + printable(name, 64) + ": " + why};
    }
  }
  auto skeleton = wire::from_proto(r.skeleton());
  if (!skeleton.ok()) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "the skeleton of '" + r.name() + "': " + skeleton.error().message};
  }
  const double ft = r.frame_time();
  if (!(std::isfinite(ft) && ft > 0.0 && 1.0 / ft >= kMinRateHz && 1.0 / ft <= kMaxRateHz)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST,
                   fmt::format("frame time {} s: the rate must be within [{}, {}] Hz", ft, kMinRateHz, kMaxRateHz)};
  }
  if (!(std::isfinite(r.metres_per_unit()) && r.metres_per_unit() >= 0.0)) {
    return Refusal{pb::ERROR_CODE_BAD_REQUEST, "metres per unit must be 0 (unknown) or positive"};
  }
  return std::move(skeleton).value();
}

}  // namespace gmr::server
