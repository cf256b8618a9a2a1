// UdpPublisher's batching: one tick's frames leave in a few sendmmsg calls,
// a frame's fragments as one GSO message that the kernel cuts into the same
// datagrams fragment_message makes, and the in-flight bound still holds.
#include <gtest/gtest.h>

#include <array>
#include <chrono>
#include <random>
#include <thread>

#include "gmr/wire/udp.h"
#include "transport/udp_publisher.h"

namespace gmr::server {
namespace {

std::string random_message(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::string s(n, '\0');
  for (auto& c : s) c = static_cast<char>(rng());
  return s;
}

// Reads datagrams from `socket` until `count` arrived or a second passed.
std::vector<std::string> receive(udp::socket& socket, std::size_t count) {
  std::vector<std::string> got;
  std::array<char, 65536> buf{};
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  socket.non_blocking(true);
  while (got.size() < count && std::chrono::steady_clock::now() < deadline) {
    boost::system::error_code ec;
    const std::size_t n = socket.receive(net::buffer(buf), 0, ec);
    if (ec == net::error::would_block) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
      continue;
    }
    if (ec) break;
    got.emplace_back(buf.data(), n);
  }
  return got;
}

TEST(UdpPublisher, BatchesATicksFramesAndCutsFragmentsAsFragmentMessageDoes) {
  net::io_context io;
  UdpPublisher publisher(io, 1000);
  publisher.open(net::ip::make_address("127.0.0.1"), 0);
  udp::socket receiver(io, udp::endpoint(net::ip::make_address("127.0.0.1"), 0));
  receiver.set_option(net::socket_base::receive_buffer_size(1 << 22));
  auto to = std::make_shared<UdpPublisher::Registration>();
  to->endpoint = receiver.local_endpoint();

  // One "tick": frames of one, two and many fragments, and one that fills
  // exactly whole fragments.
  const std::vector<std::size_t> sizes = {300, 1500, 20'000, 3 * wire::kMaxFragmentPayload, 0, 70'000};
  std::vector<std::string> messages;
  std::vector<std::string> want;
  for (std::size_t i = 0; i < sizes.size(); ++i) {
    messages.push_back(random_message(sizes[i], static_cast<unsigned>(i)));
    ASSERT_TRUE(publisher.send(to, messages.back()));
    for (auto& d : wire::fragment_message(static_cast<std::uint32_t>(i), messages.back())) want.push_back(d);
  }
  EXPECT_EQ(to->in_flight, want.size());
  EXPECT_EQ(publisher.send_calls(), 0u) << "nothing goes before the tick's handlers are done";
  io.poll();
  EXPECT_EQ(to->in_flight, 0u);
  EXPECT_EQ(publisher.datagrams_sent(), want.size());
  // One call for the whole batch (fewer than 256 entries).
  EXPECT_EQ(publisher.send_calls(), 1u);

  const auto got = receive(receiver, want.size());
  ASSERT_EQ(got.size(), want.size());
  // Loopback keeps order: the datagrams are exactly fragment_message's.
  for (std::size_t i = 0; i < want.size(); ++i) ASSERT_EQ(got[i], want[i]) << "datagram " << i;
  // And they reassemble into the messages.
  wire::Reassembler r;
  std::vector<std::string> whole;
  for (const auto& d : got) {
    if (auto m = r.add(d)) whole.push_back(*m);
  }
  EXPECT_EQ(whole, messages);
}

TEST(UdpPublisher, BoundsDatagramsInFlightPerRegistration) {
  net::io_context io;
  UdpPublisher publisher(io, 4);
  publisher.open(net::ip::make_address("127.0.0.1"), 0);
  udp::socket receiver(io, udp::endpoint(net::ip::make_address("127.0.0.1"), 0));
  auto to = std::make_shared<UdpPublisher::Registration>();
  auto unregistered = std::make_shared<UdpPublisher::Registration>();
  to->endpoint = receiver.local_endpoint();
  const std::string three(2 * wire::kMaxFragmentPayload + 1, 'x');  // three datagrams
  EXPECT_TRUE(publisher.send(to, three));
  EXPECT_FALSE(publisher.send(to, three)) << "3 + 3 > 4 in flight";
  EXPECT_TRUE(publisher.send(to, "one"));
  EXPECT_FALSE(publisher.send(to, "one"));
  EXPECT_FALSE(publisher.send(unregistered, "one")) << "no address yet";
  io.poll();
  EXPECT_EQ(to->in_flight, 0u);
  EXPECT_TRUE(publisher.send(to, three)) << "sent datagrams no longer count";
  publisher.close();
  io.restart();  // poll() ran out of work above
  io.poll();
  EXPECT_EQ(to->in_flight, 0u) << "closing gives the unsent ones back";
  EXPECT_FALSE(publisher.send(to, "one"));
}

// A registration's lane is congested while a datagram batched for it has
// waited longer than set_congested_after without reaching the kernel (the
// stream then skips computing its frames); not before, and not once sent.
TEST(UdpPublisher, CongestedWhileTheOldestUnsentDatagramWaitsTooLong) {
  net::io_context io;
  UdpPublisher publisher(io, 1000);
  publisher.set_congested_after(std::chrono::milliseconds(20));
  publisher.open(net::ip::make_address("127.0.0.1"), 0);
  udp::socket receiver(io, udp::endpoint(net::ip::make_address("127.0.0.1"), 0));
  auto to = std::make_shared<UdpPublisher::Registration>();
  to->endpoint = receiver.local_endpoint();
  EXPECT_FALSE(publisher.congested(*to)) << "nothing waits";
  for (int round = 0; round < 2; ++round) {
    ASSERT_TRUE(publisher.send(to, "a frame"));
    EXPECT_FALSE(publisher.congested(*to)) << "it has just been batched";
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
    ASSERT_TRUE(publisher.send(to, "a later frame"));  // the oldest one counts
    EXPECT_TRUE(publisher.congested(*to)) << "round " << round;
    io.restart();
    io.poll();  // the lane sends the batch
    EXPECT_EQ(to->in_flight, 0u);
    EXPECT_FALSE(publisher.congested(*to)) << "round " << round;
  }
  ASSERT_TRUE(publisher.send(to, "unsent"));
  publisher.close();
  io.restart();
  io.poll();
  EXPECT_FALSE(publisher.congested(*to)) << "closing gives back what waited";
}

}  // namespace
}  // namespace gmr::server
