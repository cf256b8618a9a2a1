// gmr::wire: TCP framing, UDP fragments and reassembly, shared frame encoding,
// skeleton conversion.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <limits>
#include <random>

#include "gmr/demo/demo_library.h"
#include "gmr/wire/convert.h"
#include "gmr/wire/frames.h"
#include "gmr/wire/framing.h"
#include "gmr/wire/udp.h"

namespace {

namespace pb = gmr::stream::v1;

TEST(Framing, LengthPrefixIsBigEndianAndCapped) {
  pb::ClientMessage m;
  m.mutable_get_skeleton()->set_motion("walk");
  const std::string framed = gmr::wire::frame_message(m).value();
  ASSERT_GE(framed.size(), gmr::wire::kLengthPrefixBytes);
  std::array<std::uint8_t, gmr::wire::kLengthPrefixBytes> prefix{};
  std::copy_n(framed.begin(), prefix.size(), prefix.begin());
  EXPECT_EQ(gmr::wire::read_length_prefix(prefix), framed.size() - prefix.size());
  gmr::wire::write_length_prefix(0x01020304u, prefix);
  EXPECT_EQ(prefix, (std::array<std::uint8_t, 4>{1, 2, 3, 4}));
  EXPECT_TRUE(gmr::wire::check_length(1000, 1000).ok());
  EXPECT_FALSE(gmr::wire::check_length(1001, 1000).ok());
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

// A message given in two pieces (a frame's head, the body its stream shares)
// is cut into exactly the datagrams of the joined message, wherever the cut
// between the pieces falls against the fragment boundaries.
TEST(UdpFragments, TwoPiecesGiveTheDatagramsOfTheJoinedMessage) {
  using gmr::wire::kMaxFragmentPayload;
  std::size_t cases = 0;
  for (std::size_t size :
       {std::size_t{0}, std::size_t{1}, kMaxFragmentPayload, kMaxFragmentPayload + 1, 3 * kMaxFragmentPayload + 17}) {
    const std::string message = random_bytes(size, static_cast<unsigned>(size) + 7);
    std::string joined;
    gmr::wire::append_fragments(joined, 9, message);
    for (std::size_t cut : {std::size_t{0}, std::size_t{1}, size / 2, kMaxFragmentPayload - 1, kMaxFragmentPayload,
                            kMaxFragmentPayload + 1, size}) {
      if (cut > size) continue;
      std::string pieces = "prefix";  // appended after what is there
      const std::size_t n = gmr::wire::append_fragments(pieces, 9, std::string_view(message).substr(0, cut),
                                                        std::string_view(message).substr(cut));
      EXPECT_EQ(n, gmr::wire::fragment_count(size));
      EXPECT_EQ(pieces, "prefix" + joined) << "size " << size << ", cut at " << cut;
      ++cases;
    }
  }
  EXPECT_EQ(cases, 27u);
}

// The fragments' bytes as docs/protocol.md gives them (what the Python,
// C# and Godot clients parse): "GMRU", version 2, kind 2, two zero bytes,
// then message id, index, count and total size big-endian, then the bytes.
TEST(UdpFragments, EachFragmentIsTheDocumentedHeaderThenItsShareOfTheMessage) {
  using gmr::wire::kMaxFragmentPayload;
  const std::string message = random_bytes(2 * kMaxFragmentPayload + 5, 3);
  std::string out = "before";
  ASSERT_EQ(gmr::wire::append_fragments(out, 0x01020304u, std::string_view(message).substr(0, 30),
                                        std::string_view(message).substr(30)),
            3u);
  std::string want = "before";
  const std::uint32_t total = static_cast<std::uint32_t>(message.size());
  for (std::uint16_t i = 0; i < 3; ++i) {
    want += std::string("GMRU\x02\x02\x00\x00\x01\x02\x03\x04", 12);
    want += {'\0', static_cast<char>(i), '\0', '\3'};
    want += {static_cast<char>(total >> 24), static_cast<char>(total >> 16), static_cast<char>(total >> 8),
             static_cast<char>(total)};
    want += message.substr(i * kMaxFragmentPayload, kMaxFragmentPayload);
  }
  EXPECT_EQ(out, want);
  EXPECT_EQ(out.size() - 6, 2 * gmr::wire::kMaxDatagramBytes + gmr::wire::kFragmentHeaderBytes + 5);
}

TEST(UdpFragments, ReassembleExactlyInAnyOrderWithDuplicates) {
  for (std::size_t size : {std::size_t{0}, std::size_t{1}, gmr::wire::kMaxFragmentPayload,
                           gmr::wire::kMaxFragmentPayload + 1, std::size_t{10000}}) {
    const std::string message = random_bytes(size, static_cast<unsigned>(size));
    auto datagrams = gmr::wire::fragment_message(42, message);
    EXPECT_EQ(datagrams.size(),
              std::max<std::size_t>(1, (size + gmr::wire::kMaxFragmentPayload - 1) / gmr::wire::kMaxFragmentPayload));
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
  bad_count[gmr::wire::kUdpHeaderBytes + 7] = 9;  // count that does not match the total
  std::string bad_magic = ds[2];
  bad_magic[0] = 'X';
  EXPECT_FALSE(r.add(truncated));
  EXPECT_FALSE(r.add(bad_count));
  EXPECT_FALSE(r.add(bad_magic));
  EXPECT_FALSE(r.add("short"));
  EXPECT_FALSE(r.add(gmr::wire::make_register_datagram({})));
  EXPECT_EQ(r.malformed(), 5u);
  EXPECT_EQ(r.completed(), 0u);
}

TEST(UdpRegister, RoundTripsAndRejectsOtherBytes) {
  gmr::wire::UdpToken token, cookie;
  for (std::size_t i = 0; i < token.size(); ++i) {
    token[i] = static_cast<std::uint8_t>(i * 17 + 3);
    cookie[i] = static_cast<std::uint8_t>(255 - i);
  }
  const auto d = gmr::wire::make_register_datagram(token);
  EXPECT_EQ(d.size(), gmr::wire::kRegisterBytes);
  EXPECT_EQ(gmr::wire::parse_register_datagram(d), token);
  EXPECT_FALSE(gmr::wire::parse_register_datagram(d.substr(1)));
  EXPECT_FALSE(gmr::wire::parse_register_datagram(d + "x"));
  std::string wrong_kind = d;
  wrong_kind[5] = 2;
  EXPECT_FALSE(gmr::wire::parse_register_datagram(wrong_kind));
  std::string version_1 = d;
  version_1[4] = 1;
  EXPECT_FALSE(gmr::wire::parse_register_datagram(version_1));
  // The challenge is no larger than the registration it answers.
  const auto ch = gmr::wire::make_challenge_datagram(cookie);
  EXPECT_LE(ch.size(), d.size());
  EXPECT_EQ(gmr::wire::parse_challenge_datagram(ch), cookie);
  EXPECT_FALSE(gmr::wire::parse_challenge_datagram(d));
  const auto confirm = gmr::wire::parse_confirm_datagram(gmr::wire::make_confirm_datagram(token, cookie));
  ASSERT_TRUE(confirm.has_value());
  EXPECT_EQ(confirm->token, token);
  EXPECT_EQ(confirm->cookie, cookie);
  EXPECT_FALSE(gmr::wire::parse_confirm_datagram(ch));
  EXPECT_TRUE(gmr::wire::same_token(token, token));
  for (std::size_t i = 0; i < token.size(); ++i) {
    auto other = token;
    other[i] ^= 0x80;
    EXPECT_FALSE(gmr::wire::same_token(token, other)) << i;
  }
}

// The shared body after a subscriber's head is one length-prefixed
// ServerMessage, and decode_frame gives back every value, in both precisions.
TEST(FrameEncoding, SharedBodyPlusSubscriberHeadDecodesToTheFrame) {
  const std::vector<double> p{1.5, -2.25, 3.0, 0.1, 0.2, 0.3};
  const std::vector<double> q{0.5, 0.5, 0.5, 0.5, 0, 0, 0, 1};  // x y z w
  const std::vector<float> pf(p.begin(), p.end()), qf(q.begin(), q.end());
  for (bool float64 : {true, false}) {
    gmr::wire::FrameContent c;
    c.skeleton_version = 3;
    c.frame_index = 17;
    c.motion_time = 17 / 120.0;
    c.sequence = 99;
    c.server_send_time_ns = 123456789;
    c.float64 = float64;
    if (float64) {
      c.positions_f64 = p;
      c.orientations_f64 = q;
    } else {
      c.positions = pf;
      c.orientations = qf;
    }
    const std::string body = gmr::wire::encode_frame_body(c);
    // Ids of every varint length, up to the largest (the head's longest).
    struct Ids {
      std::uint32_t view, subscription;
      std::uint64_t stream;
    };
    constexpr std::uint32_t kMax32 = std::numeric_limits<std::uint32_t>::max();
    for (const Ids& ids : {Ids{1, 2, 5}, Ids{300, 301, 5}, Ids{70000, 70001, 1u << 20},
                           Ids{kMax32, kMax32, std::numeric_limits<std::uint64_t>::max()}}) {
      gmr::wire::FrameHead head = gmr::wire::frame_head_for(ids.view, ids.subscription, ids.stream, body.size(), true);
      ASSERT_LE(head.size(), gmr::wire::FrameHead::kCapacity);
      // The head ends with the write stamp, filled in as the frame leaves.
      const std::int64_t written = 1'700'000'000'123'456'789 + ids.view;
      head.set_write_stamp(written);
      const std::string whole = std::string(head.view()) + body;
      std::array<std::uint8_t, gmr::wire::kLengthPrefixBytes> prefix{};
      std::copy_n(whole.begin(), prefix.size(), prefix.begin());
      ASSERT_EQ(gmr::wire::read_length_prefix(prefix), whole.size() - prefix.size());
      const std::string out = whole.substr(prefix.size());
      EXPECT_EQ(out, gmr::wire::frame_message_for(ids.view, ids.subscription, ids.stream, body, written));
      pb::ServerMessage m;
      ASSERT_TRUE(m.ParseFromString(out));
      ASSERT_TRUE(m.has_frame());
      auto f = gmr::wire::decode_frame(m.frame());
      ASSERT_TRUE(f.ok()) << f.error().to_string();
      EXPECT_EQ(f->view_id, ids.view);
      EXPECT_EQ(f->subscription_id, ids.subscription);
      EXPECT_EQ(f->stream_id, ids.stream);
      EXPECT_EQ(f->skeleton_version, 3u);
      EXPECT_EQ(f->frame_index, 17u);
      EXPECT_EQ(f->motion_time, 17 / 120.0);
      EXPECT_EQ(f->sequence, 99u);
      EXPECT_EQ(f->server_send_time_ns, 123456789);
      EXPECT_EQ(f->server_write_time_ns, written);
      EXPECT_EQ(f->float64, float64);
      ASSERT_EQ(f->positions.size(), 2u);
      EXPECT_EQ(f->positions[0], Eigen::Vector3d(1.5, -2.25, 3.0));
      EXPECT_EQ(f->positions[1].x(), float64 ? 0.1 : static_cast<double>(0.1f));
      ASSERT_EQ(f->orientations.size(), 2u);
      EXPECT_EQ(f->orientations[0].w(), 0.5);
      EXPECT_EQ(f->orientations[1].w(), 1.0);
      EXPECT_EQ(f->orientations[1].x(), 0.0);
    }
  }
}

// Frame k of a series: k's bits choose the precision, orientations, local
// transforms and all zeros (no joints, every field 0); otherwise `joints`
// joints of random values and `version`. Its content points into it.
struct RandomFrame {
  RandomFrame(int k, std::size_t joints_unless_zeros, std::uint32_t version, std::mt19937& rng)
      : float64((k & 1) != 0), zeros((k & 8) != 0), joints(zeros ? 0 : joints_unless_zeros) {
    std::uniform_real_distribution<double> value(-1e4, 1e4);
    const bool orientations = (k & 2) != 0, locals = (k & 4) != 0;
    p.resize(3 * joints);
    q.resize(orientations ? 4 * joints : 0);
    lr.resize(locals ? 4 * joints : 0);
    lt.resize(locals ? 3 * joints : 0);
    for (auto* v : {&p, &q, &lr, &lt}) {
      for (auto& x : *v) x = value(rng);
    }
    pf.assign(p.begin(), p.end());
    qf.assign(q.begin(), q.end());
    lrf.assign(lr.begin(), lr.end());
    ltf.assign(lt.begin(), lt.end());
    gmr::wire::FrameContent& c = content;
    c.skeleton_version = zeros ? 0 : version;
    c.frame_index = zeros ? 0 : (std::uint64_t{1} << (k % 64));
    c.motion_time = zeros ? 0.0 : value(rng);
    c.sequence = zeros ? 0 : std::numeric_limits<std::uint64_t>::max() - static_cast<std::uint64_t>(k);
    c.server_send_time_ns = zeros ? 0 : (k % 3 == 0 ? -123456789 : 1'700'000'000'000'000'000 + k);
    c.float64 = float64;
    if (float64) {
      c.positions_f64 = p;
      c.orientations_f64 = q;
      c.local_rotations_f64 = lr;
      c.local_translations_f64 = lt;
    } else {
      c.positions = pf;
      c.orientations = qf;
      c.local_rotations = lrf;
      c.local_translations = ltf;
    }
  }
  RandomFrame(const RandomFrame&) = delete;
  RandomFrame& operator=(const RandomFrame&) = delete;

  bool float64, zeros;
  std::size_t joints;
  std::vector<double> p, q, lr, lt;
  std::vector<float> pf, qf, lrf, ltf;
  gmr::wire::FrameContent content;
};

// encode_frame_body writes the fields itself: byte for byte what protobuf
// writes for the same Frame, zeros and empty lists left out, in both
// precisions, with and without orientations and local transforms.
TEST(FrameEncoding, TheBodyIsWhatProtobufWrites) {
  std::mt19937 rng(7);
  int cases = 0;
  for (int k = 0; k < 64; ++k) {
    const RandomFrame f(k, static_cast<std::size_t>(1 + k % 31), static_cast<std::uint32_t>(k * 1000), rng);
    const gmr::wire::FrameContent& c = f.content;
    pb::Frame expected;
    expected.set_skeleton_version(c.skeleton_version);
    expected.set_frame_index(c.frame_index);
    expected.set_motion_time(c.motion_time);
    expected.set_sequence(c.sequence);
    expected.set_server_send_time_ns(c.server_send_time_ns);
    if (f.float64) {
      expected.mutable_positions_f64()->Add(f.p.begin(), f.p.end());
      expected.mutable_orientations_f64()->Add(f.q.begin(), f.q.end());
      expected.mutable_local_rotations_f64()->Add(f.lr.begin(), f.lr.end());
      expected.mutable_local_translations_f64()->Add(f.lt.begin(), f.lt.end());
    } else {
      expected.mutable_positions()->Add(f.pf.begin(), f.pf.end());
      expected.mutable_orientations()->Add(f.qf.begin(), f.qf.end());
      expected.mutable_local_rotations()->Add(f.lrf.begin(), f.lrf.end());
      expected.mutable_local_translations()->Add(f.ltf.begin(), f.ltf.end());
    }
    EXPECT_EQ(gmr::wire::encode_frame_body(c), expected.SerializeAsString()) << "case " << k;
    ++cases;
  }
  EXPECT_EQ(cases, 64);
}

enum class Reading { kRead, kLeftToProtobuf };

// What read_frame_message does with `bytes`, having checked that when it
// reads them protobuf parses the same frame: the same values, or the same
// error. `kept` is decoded into again, as a client does.
Reading read_as_protobuf_does(const std::string& bytes, gmr::wire::FrameValues& kept) {
  gmr::wire::FrameFields fields;
  if (!gmr::wire::read_frame_message(bytes, fields)) return Reading::kLeftToProtobuf;
  pb::ServerMessage m;
  EXPECT_TRUE(m.ParseFromString(bytes) && m.has_frame()) << "read what protobuf does not parse as a frame";
  const auto by_protobuf = gmr::wire::decode_frame(m.frame());
  const gmr::Status read = gmr::wire::unpack_frame(fields, kept);
  EXPECT_EQ(read.ok(), by_protobuf.ok());
  if (read.ok() && by_protobuf.ok()) {
    EXPECT_TRUE(gmr::wire::same_bits(kept, *by_protobuf)) << "frame " << kept.frame_index;
  } else if (!read.ok() && !by_protobuf.ok()) {
    EXPECT_EQ(read.error().message, by_protobuf.error().message);
  }
  return Reading::kRead;
}

// Every frame a server writes, of every kind, is read in place with
// protobuf's values, into one FrameValues after another of other sizes.
TEST(FrameReading, ReadsEveryFrameAServerWritesWithProtobufsValues) {
  std::mt19937 rng(11);
  gmr::wire::FrameValues kept;
  int read = 0;
  for (int k = 0; k < 128; ++k) {
    const RandomFrame f(k, static_cast<std::size_t>(1 + (k * 7) % 40), static_cast<std::uint32_t>(k) << (k % 25), rng);
    const std::uint32_t id = f.zeros ? 0 : std::numeric_limits<std::uint32_t>::max() >> (k % 32);
    const std::string message = gmr::wire::frame_message_for(id, id / 2 + 1, std::uint64_t{id} << (k % 32),
                                                             gmr::wire::encode_frame_body(f.content), f.zeros ? 0 : -k);
    ASSERT_EQ(read_as_protobuf_does(message, kept), Reading::kRead) << "case " << k;
    EXPECT_EQ(kept.positions.size(), f.joints);
    EXPECT_EQ(kept.float64, f.float64 && f.joints > 0);
    ++read;
  }
  EXPECT_EQ(read, 128);
}

// Bytes that are not quite what a server writes: read in place only where
// protobuf parses the same frame (an unknown field, a field repeated: the
// last value), left to protobuf otherwise (an unpacked list, a list in two
// pieces, a request id beside the frame, varints protobuf would truncate or
// refuse), and never read differently; then every cut and one-byte change of
// a real frame, and random bytes after a frame's tag.
TEST(FrameReading, LeavesToProtobufWhatItDoesNotReadAndNeverDisagrees) {
  gmr::wire::FrameContent c;
  c.skeleton_version = 2;
  c.frame_index = 40;
  c.sequence = 7;
  c.server_send_time_ns = 1'700'000'000'000'000'000;
  const std::vector<float> p{1, 2, 3, 4, 5, 6};
  c.positions = p;
  const std::string body = gmr::wire::encode_frame_body(c);
  auto frame_of = [](const std::string& frame_fields) {
    std::string m = "\xb2\x01";  // ServerMessage.frame, length-delimited
    std::uint64_t n = frame_fields.size();
    for (; n >= 0x80; n >>= 7) m += static_cast<char>((n & 0x7f) | 0x80);
    return m + static_cast<char>(n) + frame_fields;
  };
  const std::string floats(reinterpret_cast<const char*>(p.data()), 24);
  struct Case {
    const char* what;
    std::string bytes;
    Reading expected;
  };
  const std::vector<Case> cases{
      {"a server's frame", frame_of("\x08\x01\x10\x02" + body), Reading::kRead},
      {"an unknown varint field", frame_of(body + std::string("\xa8\x06\x05", 3)), Reading::kRead},
      {"an unknown length-delimited field", frame_of(body + std::string("\xaa\x06\x02xy", 5)), Reading::kRead},
      {"a known field of another wire type", frame_of(std::string("\x0d\x01\x02\x03\x04", 5) + body), Reading::kRead},
      {"a field given twice (the last counts)", frame_of(body + std::string("\x98\x01\x09", 3)), Reading::kRead},
      {"an empty frame", frame_of(""), Reading::kRead},
      {"a non-minimal varint", frame_of(std::string("\x08\x81\x80\x00", 4) + body), Reading::kRead},
      {"positions unpacked", frame_of(std::string("\xad\x01", 2) + floats.substr(0, 4)), Reading::kLeftToProtobuf},
      {"positions in two pieces",
       frame_of(std::string("\xaa\x01\x0c", 3) + floats.substr(0, 12) + std::string("\xaa\x01\x0c", 3) +
                floats.substr(12)),
       Reading::kLeftToProtobuf},
      {"a request id beside the frame", std::string("\x08\x05", 2) + frame_of(body), Reading::kLeftToProtobuf},
      {"bytes after the frame", frame_of(body) + std::string("\x08\x05", 2), Reading::kLeftToProtobuf},
      {"another message", std::string("\xa2\x01\x00", 3), Reading::kLeftToProtobuf},
      {"a uint32 past 32 bits", frame_of(std::string("\x08\x80\x80\x80\x80\x10", 6) + body), Reading::kLeftToProtobuf},
      {"a varint past 64 bits", frame_of(std::string("\x18\xff\xff\xff\xff\xff\xff\xff\xff\xff\x7f", 11)),
       Reading::kLeftToProtobuf},
      {"a tag of six bytes", frame_of(std::string("\x88\x80\x80\x80\x80\x00\x01", 7)), Reading::kLeftToProtobuf},
      {"a group", frame_of(std::string("\xab\x06\xac\x06", 4)), Reading::kLeftToProtobuf},
      {"positions of 5 bytes", frame_of(std::string("\xaa\x01\x05", 3) + floats.substr(0, 5)),
       Reading::kLeftToProtobuf},
      {"a length past the end", frame_of(body).substr(0, 10), Reading::kLeftToProtobuf},
  };
  gmr::wire::FrameValues kept;
  for (const Case& k : cases) EXPECT_EQ(read_as_protobuf_does(k.bytes, kept), k.expected) << k.what;

  // Every cut and every one-byte change of a whole frame (ids, stamp, body).
  const std::string whole = gmr::wire::frame_message_for(300, 70000, 5, body, 99);
  int read = 0, left = 0;
  auto count = [&](const std::string& bytes) {
    (read_as_protobuf_does(bytes, kept) == Reading::kRead ? read : left)++;
  };
  for (std::size_t n = 0; n < whole.size(); ++n) count(whole.substr(0, n));
  for (std::size_t i = 0; i < whole.size(); ++i) {
    for (int b : {0x00, 0x01, 0x07, 0x08, 0x7f, 0x80, 0xff}) {
      std::string changed = whole;
      changed[i] = static_cast<char>(b);
      count(changed);
    }
  }
  std::mt19937 rng(5);
  for (int k = 0; k < 20000; ++k) {
    std::string fields(static_cast<std::size_t>(rng() % 40), '\0');
    for (auto& ch : fields) ch = static_cast<char>(rng() % 4 == 0 ? rng() % 0x40 : rng());
    count(frame_of(fields));
  }
  EXPECT_EQ(read + left, static_cast<int>(whole.size() * 8) + 20000);
  // Both ways taken many times: the comparisons above were made.
  EXPECT_GT(read, 1000);
  EXPECT_GT(left, 1000);
}

TEST(FrameDecoding, RefusesCountsThatDoNotFormWholeValues) {
  pb::Frame f;
  for (int i = 0; i < 4; ++i) f.add_positions(1.0f);
  auto r = gmr::wire::decode_frame(f);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().kind, gmr::ErrorKind::kInvalidData);
  f.add_positions(1.0f), f.add_positions(1.0f);          // two whole positions
  for (int i = 0; i < 5; ++i) f.add_orientations(0.0f);  // neither 0 nor 8
  EXPECT_FALSE(gmr::wire::decode_frame(f).ok());
  for (int i = 0; i < 3; ++i) f.add_orientations(0.0f);
  EXPECT_TRUE(gmr::wire::decode_frame(f).ok());
  // Local transforms: both or neither, one per position.
  for (int i = 0; i < 8; ++i) f.add_local_rotations(i % 4 == 3 ? 1.0f : 0.0f);
  auto no_translations = gmr::wire::decode_frame(f);
  ASSERT_FALSE(no_translations.ok());
  EXPECT_NE(no_translations.error().message.find("8 local rotation and 0 local translation values for 2 positions"),
            std::string::npos)
      << no_translations.error().message;
  for (int i = 0; i < 6; ++i) f.add_local_translations(static_cast<float>(i));
  auto locals = gmr::wire::decode_frame(f);
  ASSERT_TRUE(locals.ok()) << locals.error().to_string();
  ASSERT_EQ(locals->local_rotations.size(), 2u);
  EXPECT_EQ(locals->local_rotations[1].w(), 1.0);
  EXPECT_EQ(locals->local_translations[1], Eigen::Vector3d(3, 4, 5));

  pb::FrameBlock b;
  b.set_begin(2);
  b.set_end(4);
  b.add_joints(0);
  for (int i = 0; i < 3; ++i) b.add_positions(0.5);  // one frame of two
  EXPECT_FALSE(gmr::wire::decode_block(b).ok());
  for (int i = 0; i < 3; ++i) b.add_positions(0.5);
  auto ok = gmr::wire::decode_block(b);
  ASSERT_TRUE(ok.ok()) << ok.error().to_string();
  EXPECT_EQ(ok->positions.size(), 2u);
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
