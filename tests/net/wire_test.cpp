// gmr::wire: TCP framing, UDP fragments and reassembly, shared frame encoding,
// skeleton conversion.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "gmr/demo/demo_library.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/frame_encoding.h"
#include "gmr/wire/framing.h"
#include "gmr/wire/udp.h"

namespace {

namespace pb = gmr::stream::v1;
using gmr::wire::StreamDecoder;

TEST(Framing, RoundTripsMessagesFedByteByByte) {
  pb::ClientMessage a;
  a.set_request_id(7);
  a.mutable_create_view()->set_motion("walk");
  pb::ClientMessage b;
  b.set_request_id(8);
  b.mutable_list_motions();
  const std::string stream = gmr::wire::frame_message(a).value() + gmr::wire::frame_message(b).value();
  StreamDecoder d;
  std::vector<std::string> got;
  for (char c : stream) {
    d.feed(std::string_view(&c, 1));
    std::string out;
    while (d.next(out) == StreamDecoder::Next::kMessage) got.push_back(out);
  }
  ASSERT_EQ(got.size(), 2u);
  pb::ClientMessage ra, rb;
  ASSERT_TRUE(ra.ParseFromString(got[0]));
  ASSERT_TRUE(rb.ParseFromString(got[1]));
  EXPECT_EQ(ra.request_id(), 7u);
  EXPECT_EQ(ra.create_view().motion(), "walk");
  EXPECT_TRUE(rb.has_list_motions());
  EXPECT_EQ(d.buffered(), 0u);
}

TEST(Framing, RefusesAnOversizedLengthBeforeBufferingTheBody) {
  StreamDecoder d(1024);
  d.feed(std::string("\x00\x00\x04\x01", 4));  // 1025 > 1024
  std::string out;
  EXPECT_EQ(d.next(out), StreamDecoder::Next::kError);
  EXPECT_NE(d.error().message.find("1025"), std::string::npos) << d.error().message;
  EXPECT_NE(d.error().message.find("1024"), std::string::npos) << d.error().message;
  d.feed("more");
  EXPECT_EQ(d.next(out), StreamDecoder::Next::kError);  // stays failed
  EXPECT_EQ(d.buffered(), 0u);
}

TEST(Framing, WaitsForATruncatedPrefixOrBody) {
  StreamDecoder d;
  std::string out;
  d.feed(std::string("\x00\x00", 2));
  EXPECT_EQ(d.next(out), StreamDecoder::Next::kNeedMore);
  d.feed(std::string("\x00\x05" "abc", 5));
  EXPECT_EQ(d.next(out), StreamDecoder::Next::kNeedMore);
  d.feed("de");
  ASSERT_EQ(d.next(out), StreamDecoder::Next::kMessage);
  EXPECT_EQ(out, "abcde");
}

TEST(Framing, FrameMessageRefusesAMessageAboveTheCap) {
  pb::ClientMessage m;
  m.mutable_get_skeleton()->set_motion(std::string(2000, 'x'));
  EXPECT_FALSE(gmr::wire::frame_message(m, 1000).ok());
  EXPECT_TRUE(gmr::wire::frame_message(m, 4000).ok());
}

std::string random_bytes(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::string s(n, '\0');
  for (auto& c : s) c = static_cast<char>(rng());
  return s;
}

TEST(UdpFragments, ReassembleExactlyInAnyOrderWithDuplicates) {
  for (std::size_t size : {std::size_t{0}, std::size_t{1}, gmr::wire::kMaxFragmentPayload,
                           gmr::wire::kMaxFragmentPayload + 1, std::size_t{10000}}) {
    const std::string message = random_bytes(size, static_cast<unsigned>(size));
    auto datagrams = gmr::wire::fragment_message(42, message);
    EXPECT_EQ(datagrams.size(), std::max<std::size_t>(1, (size + gmr::wire::kMaxFragmentPayload - 1) /
                                                             gmr::wire::kMaxFragmentPayload));
    for (const auto& d : datagrams) EXPECT_LE(d.size(), gmr::wire::kMaxDatagramBytes);
    std::reverse(datagrams.begin(), datagrams.end());
    datagrams.push_back(datagrams.front());  // a duplicate after completion is ignored
    gmr::wire::Reassembler r;
    std::vector<std::string> out;
    for (const auto& d : datagrams) {
      if (auto m = r.add(d)) out.push_back(*m);
    }
    ASSERT_EQ(out.size(), 1u) << size;
    EXPECT_EQ(out[0], message);
    EXPECT_EQ(r.dropped(), 0u);
  }
}

TEST(UdpFragments, AMessageWithALostFragmentIsDroppedWhole) {
  gmr::wire::Reassembler r;
  const std::string big = random_bytes(5000, 1);
  auto lossy = gmr::wire::fragment_message(1, big);
  lossy.erase(lossy.begin() + 2);
  for (const auto& d : lossy) EXPECT_FALSE(r.add(d).has_value());
  // Later messages complete; after kMaxPartial newer incomplete ones the lost one is counted.
  for (std::uint32_t id = 2; id < 2 + gmr::wire::Reassembler::kMaxPartial; ++id) {
    auto ds = gmr::wire::fragment_message(id, big);
    r.add(ds[0]);  // incomplete
  }
  EXPECT_GE(r.dropped(), 1u);
  auto ok = gmr::wire::fragment_message(100, big);
  std::optional<std::string> got;
  for (const auto& d : ok) got = r.add(d);
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, big);
}

TEST(UdpFragments, MalformedDatagramsAreCountedAndIgnored) {
  gmr::wire::Reassembler r;
  auto ds = gmr::wire::fragment_message(5, random_bytes(3000, 2));
  std::string truncated = ds[0].substr(0, ds[0].size() - 1);  // wrong payload size for its index
  std::string bad_count = ds[1];
  bad_count[gmr::wire::kUdpHeaderBytes + 7] = 9;            // count that does not match the total
  std::string bad_magic = ds[2];
  bad_magic[0] = 'X';
  EXPECT_FALSE(r.add(truncated));
  EXPECT_FALSE(r.add(bad_count));
  EXPECT_FALSE(r.add(bad_magic));
  EXPECT_FALSE(r.add("short"));
  EXPECT_FALSE(r.add(gmr::wire::make_register_datagram(1)));
  EXPECT_EQ(r.malformed(), 5u);
  EXPECT_EQ(r.completed(), 0u);
}

TEST(UdpRegister, RoundTripsAndRejectsOtherBytes) {
  const auto d = gmr::wire::make_register_datagram(0x0123456789abcdefULL);
  EXPECT_EQ(d.size(), gmr::wire::kRegisterBytes);
  EXPECT_EQ(gmr::wire::parse_register_datagram(d), 0x0123456789abcdefULL);
  EXPECT_FALSE(gmr::wire::parse_register_datagram(d.substr(1)));
  EXPECT_FALSE(gmr::wire::parse_register_datagram(d + "x"));
  std::string wrong_kind = d;
  wrong_kind[5] = 2;
  EXPECT_FALSE(gmr::wire::parse_register_datagram(wrong_kind));
}

TEST(FrameEncoding, SharedBodyPlusSubscriberHeadIsOneServerMessage) {
  std::vector<Eigen::Vector3d> p{{1.5, -2.25, 3.0}, {0.1, 0.2, 0.3}};
  std::vector<Eigen::Quaterniond> q{Eigen::Quaterniond(0.5, 0.5, 0.5, 0.5), Eigen::Quaterniond::Identity()};
  gmr::wire::FrameContent c;
  c.skeleton_version = 3;
  c.frame_index = 17;
  c.motion_time = 17 / 120.0;
  c.sequence = 99;
  c.server_send_time_ns = 123456789;
  c.positions = p;
  c.orientations = q;
  c.float64 = true;
  const std::string body = gmr::wire::encode_frame_body(c);
  for (std::uint32_t view : {1u, 300u, 70000u}) {
    const std::string head = gmr::wire::frame_head_for(view, view + 1, 5, body.size(), true);
    const std::string whole = head + body;
    StreamDecoder d;
    d.feed(whole);
    std::string out;
    ASSERT_EQ(d.next(out), StreamDecoder::Next::kMessage);
    EXPECT_EQ(out, gmr::wire::frame_message_for(view, view + 1, 5, body));
    pb::ServerMessage m;
    ASSERT_TRUE(m.ParseFromString(out));
    ASSERT_TRUE(m.has_frame());
    const auto& f = m.frame();
    EXPECT_EQ(f.view_id(), view);
    EXPECT_EQ(f.subscription_id(), view + 1);
    EXPECT_EQ(f.stream_id(), 5u);
    EXPECT_EQ(f.skeleton_version(), 3u);
    EXPECT_EQ(f.frame_index(), 17u);
    EXPECT_EQ(f.motion_time(), 17 / 120.0);
    EXPECT_EQ(f.sequence(), 99u);
    EXPECT_EQ(f.server_send_time_ns(), 123456789);
    ASSERT_EQ(f.positions_f64_size(), 6);
    EXPECT_EQ(f.positions_f64(1), -2.25);
    ASSERT_EQ(f.orientations_f64_size(), 8);
    EXPECT_EQ(f.orientations_f64(3), 0.5);  // w of the first
    EXPECT_EQ(f.orientations_f64(7), 1.0);
  }
}

TEST(SkeletonConversion, RoundTripsTheDemoSkeleton) {
  const gmr::Skeleton s = gmr::demo_skeleton();
  pb::Skeleton m;
  gmr::wire::to_proto(s, m);
  auto back = gmr::wire::from_proto(m);
  ASSERT_TRUE(back.ok()) << back.error().to_string();
  ASSERT_EQ(back->size(), s.size());
  for (int j = 0; j < static_cast<int>(s.size()); ++j) {
    EXPECT_EQ(back->joint(j).name, s.joint(j).name);
    EXPECT_EQ(back->joint(j).parent, s.joint(j).parent);
    EXPECT_EQ(back->joint(j).offset, s.joint(j).offset);
    EXPECT_EQ(back->joint(j).channels, s.joint(j).channels);
  }
}

TEST(SkeletonConversion, RejectsInvalidSkeletonsFromTheWire) {
  pb::Skeleton m;
  auto* j = m.add_joints();
  j->set_name("a");
  j->set_parent(5);  // out of range
  j->set_soft_parent(-1);
  EXPECT_FALSE(gmr::wire::from_proto(m).ok());
  j->set_parent(-1);
  j->add_channels(static_cast<pb::ChannelType>(17));
  EXPECT_FALSE(gmr::wire::from_proto(m).ok());
}

}  // namespace
