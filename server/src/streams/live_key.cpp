#include "live_key.h"

#include <cstring>

namespace gmr::server {

LiveKey& LiveKey::put(std::string_view field) {
  key_ += std::to_string(field.size());
  key_ += ':';
  key_ += field;
  return *this;
}

LiveKey& LiveKey::put_number(double x) {
  char bytes[sizeof x];
  std::memcpy(bytes, &x, sizeof x);
  return put(std::string_view(bytes, sizeof bytes));
}

LiveKey& LiveKey::put_motion(const Motion& m, bool with_values) {
  put("motion");
  put_number(static_cast<double>(m.convention == Convention::kPreRotation));
  put_number(static_cast<double>(m.skeleton.size()));
  for (const Joint& j : m.skeleton.joints()) {
    put(j.name);
    put_number(j.parent);
    put_number(j.soft_parent);
    for (int k = 0; k < 3; ++k) put_number(j.offset[k]);
    std::string channels;
    for (ChannelType c : j.channels) channels += static_cast<char>('a' + static_cast<int>(c));
    put(channels);
  }
  if (with_values) {
    put_number(static_cast<double>(m.frame_count));
    put(std::string_view(reinterpret_cast<const char*>(m.values.data()), m.values.size() * sizeof(double)));
  }
  return *this;
}

}  // namespace gmr::server
