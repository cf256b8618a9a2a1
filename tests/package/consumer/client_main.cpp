// Links the installed gmr::client: connects to the gmr-server whose port is
// argv[1] (the installed one, started by package_test.cmake), lists its
// motions and streams ten frames of the first in Unity's conventions with
// local transforms. Exit 1 when something fails.
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <mutex>

#include "gmr/client/client.h"

int main(int argc, char** argv) {
  if (argc != 2) return 2;
  gmr::client::ClientOptions o;
  o.port = static_cast<std::uint16_t>(std::atoi(argv[1]));
  auto c = gmr::client::Client::connect(o);
  if (!c.ok()) {
    std::fprintf(stderr, "connect: %s\n", c.error().to_string().c_str());
    return 1;
  }
  auto motions = (*c)->list_motions();
  if (!motions.ok() || motions->empty()) return 1;
  auto view = (*c)->create_view(motions->front().name);
  if (!view.ok()) return 1;
  std::mutex m;
  std::condition_variable cv;
  int frames = 0;
  bool ended = false, locals = true;
  gmr::client::SubscribeOptions so;
  so.max_frames = 10;
  so.local_transforms = true;
  so.conventions.preset = gmr::ConventionPreset::kUnity;
  auto sub = (*c)->subscribe(
      view->id, so,
      [&](const gmr::client::ReceivedFrame& f) {
        std::lock_guard lock(m);
        ++frames;
        locals = locals && f.local_rotations.size() == f.positions.size();
      },
      [&](const gmr::client::SubscriptionEnd&) {
        std::lock_guard lock(m);
        ended = true;
        cv.notify_all();
      });
  if (!sub.ok()) return 1;
  std::unique_lock lock(m);
  cv.wait_for(lock, std::chrono::seconds(20), [&] { return ended; });
  if (frames != 10 || !locals || sub->rest.translations.size() != view->skeleton.size()) return 1;
  std::printf("client consumer: %zu motions, %d frames of %s with local transforms\n", motions->size(), frames,
              motions->front().name.c_str());
  return 0;
}
