// A subscription target's frames: each its own head (its ids, the length of
// the shared body it goes before) then that body, whatever the bodies' sizes
// and streams from one frame to the next (a target keeps its last head and
// makes it again when either changes).
#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "recording_outbox.h"
#include "streams/targets.h"

namespace gmr::test {
namespace {

struct NoEvents final : server::SubscriptionEvents {
  void subscription_ended(std::uint32_t, std::uint64_t, const std::string&) override {}
};

// A shared body: the Frame fields after the per-subscriber ones, here a frame
// index and `joints` positions (so its size crosses varint lengths).
std::shared_ptr<const std::string> body(std::uint64_t frame_index, int joints) {
  pb::Frame f;
  f.set_frame_index(frame_index);
  for (int i = 0; i < 3 * joints; ++i) f.add_positions(static_cast<float>(i) * 0.5f);
  return std::make_shared<const std::string>(f.SerializeAsString());
}

TEST(SubscriptionTargets, EachFrameCarriesItsOwnHeadWhateverTheBodySizeAndStream) {
  auto events = std::make_shared<NoEvents>();
  auto box = std::make_shared<RecordingOutbox>();
  server::TcpTarget target(events, box, /*subscription=*/300, /*view=*/5);
  struct Sent {
    std::uint64_t stream, frame;
    int joints;
  };
  // Sizes kept, grown past a one-byte length (127), shrunk, kept, and a
  // stream changed at the same size.
  const Sent sent[] = {{9, 0, 2}, {9, 1, 2}, {9, 2, 40}, {9, 3, 40}, {9, 4, 1}, {9, 5, 1}, {70000, 6, 1}, {9, 7, 1}};
  for (const Sent& s : sent) target.deliver(s.stream, body(s.frame, s.joints), server::Clock::now());
  ASSERT_EQ(box->frames.size(), std::size(sent));
  for (std::size_t i = 0; i < std::size(sent); ++i) {
    const pb::Frame& f = box->frames[i].frame();
    EXPECT_EQ(f.view_id(), 5u) << i;
    EXPECT_EQ(f.subscription_id(), 300u) << i;
    EXPECT_EQ(f.stream_id(), sent[i].stream) << i;
    EXPECT_EQ(f.frame_index(), sent[i].frame) << i;
    EXPECT_EQ(f.positions_size(), 3 * sent[i].joints) << i;
    EXPECT_EQ(box->keys[i], 300u) << i;
  }
}

}  // namespace
}  // namespace gmr::test
