// What a server sends the C++ client, as the client handles it: the input is
// a sequence of length-prefixed ServerMessages (the first byte of each says
// TCP or UDP), handed one by one to Client::Impl::take_message (a frame read
// in place, anything else parsed by protobuf: on_message) with three
// subscriptions registered (4, 1 and an unstated number of values). Any
// messages give callbacks or counted drops, never a crash, a leak or a frame
// whose values do not fit its subscription (checked here: a failed check
// aborts).
#include <array>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>

#include "client_impl.h"

namespace client = gmr::client;

namespace {

std::shared_ptr<client::Client::Impl::Sub> sub(std::size_t values) {
  auto s = std::make_shared<client::Client::Impl::Sub>();
  s->values = values;
  s->skeleton_version = 1;
  // The count in effect when the frame is handed on (a skeleton change may set another).
  s->on_frame = [self = s.get()](const client::ReceivedFrame& f) {
    if (self->values != 0 && f.positions.size() != self->values) std::abort();
    if (!f.orientations.empty() && f.orientations.size() != f.positions.size()) std::abort();
  };
  s->on_end = [](const client::SubscriptionEnd&) {};
  s->on_skeleton = [](const client::SkeletonChange& c) {
    for (const int j : c.joints) {
      if (j < 0 || static_cast<std::size_t>(j) >= c.skeleton.size()) std::abort();
    }
  };
  return s;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  auto loop = std::make_shared<client::Loop>();
  auto impl = std::make_shared<client::Client::Impl>(loop);
  impl->subs[1] = sub(4);
  impl->subs[2] = sub(1);
  impl->subs[3] = sub(0);
  impl->subscribes_in_flight = size % 2;  // frames for unknown subscriptions are held
  std::size_t i = 0;
  while (i + 5 <= size) {
    const bool udp = (data[i] & 1) != 0;
    const std::array<std::uint8_t, gmr::wire::kLengthPrefixBytes> prefix{data[i + 1], data[i + 2], data[i + 3],
                                                                         data[i + 4]};
    const std::size_t n = std::min<std::size_t>(gmr::wire::read_length_prefix(prefix), size - i - 5);
    (void)impl->take_message(std::string_view(reinterpret_cast<const char*>(data + i + 5), n), udp);
    i += 5 + n;
  }
  // Held end notices wait on timers: cancelled and run here, so nothing is
  // left holding the client.
  impl->shut();
  loop->io.poll();
  return 0;
}
