#include "live/announcement.h"

#include <fmt/format.h>

#include <cmath>
#include <string>
#include <string_view>

#include "gmr/wire/convert.h"
#include "streams/stream.h"

namespace gmr::server {

namespace {

constexpr std::size_t kMaxLiveNameBytes = 200;

// Why `name` cannot name a motion (empty: it can).
std::string bad_name(std::string_view name) {
  if (name.empty()) return "a live source needs a name";
  if (name.size() > kMaxLiveNameBytes) {
    return "a name of " + std::to_string(name.size()) + " bytes; at most " + std::to_string(kMaxLiveNameBytes);
  }
  for (const unsigned char c : name) {
    if (c < 0x20 || c == 0x7f) return "the name has a control character";
  }
  return {};
}

}  // namespace

std::variant<Skeleton, Refusal> check_announcement(const pb::Publish& r, const ServerConfig& cfg) {
  if (const std::string why = bad_name(r.name()); !why.empty()) return Refusal{pb::ERROR_CODE_BAD_REQUEST, why};
  if (static_cast<std::size_t>(r.skeleton().joints_size()) > cfg.max_live_joints) {
    return Refusal{pb::ERROR_CODE_RESOURCE_EXHAUSTED, "a skeleton of " + std::to_string(r.skeleton().joints_size()) +
                                                          " joints; live sources have at most " +
                                                          std::to_string(cfg.max_live_joints)};
  }
  if (r.skeleton().joints_size() == 0) return Refusal{pb::ERROR_CODE_BAD_REQUEST, "the skeleton has no joints"};
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
