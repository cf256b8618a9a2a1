// C3D reader: every real file with facts from shared/data/PROVENANCE.md, the
// CMU 02_01 cross-check against its BVH, malformed files, and small files
// built here for the processor types and storage forms the corpus lacks.
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "gmr/io/bvh.h"
#include "gmr/markers/c3d.h"
#include "gmr/markers/markers.h"
#include "gmr/markers/trc.h"
#include "markers_test_util.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "test_data.h"

namespace gmr {
namespace {

int find(const MarkerTrajectories& d, const std::string& name) {
  const auto it = std::find(d.names.begin(), d.names.end(), name);
  return it == d.names.end() ? -1 : static_cast<int>(it - d.names.begin());
}

TEST(RealFiles, CmuC3d) {
  GMR_REQUIRE_DATA();
  Warnings w;
  const auto a = test::load_marker_file("c3d/cmu_01_01.c3d", &w);
  EXPECT_TRUE(w.empty());
  EXPECT_EQ(a.marker_count(), 42u);
  EXPECT_EQ(a.frame_count, 2751u);
  EXPECT_EQ(a.frame_rate, 120.0);
  EXPECT_EQ(a.first_frame, 40);
  EXPECT_EQ(a.units, "mm");
  EXPECT_GE(find(a, "LFWT"), 0);
  EXPECT_GE(find(a, "RBAC-1"), 0);
  EXPECT_EQ(a.analog_channels, 0u);
  ASSERT_TRUE(a.validate().ok());

  const auto b = test::load_marker_file("c3d/cmu_02_01.c3d");
  EXPECT_EQ(b.marker_count(), 41u);
  EXPECT_EQ(b.frame_count, 343u);
  EXPECT_EQ(b.first_frame, 50);
  EXPECT_EQ(b.frame_rate, 120.0);
  for (const auto& n : b.names) EXPECT_EQ(n.rfind("TakeoMonday:", 0), 0u) << n;
  EXPECT_GE(find(b, "TakeoMonday:LFWT"), 0);
  EXPECT_EQ(b.missing_points(), 0u);
  // Residuals: present for every valid point, never negative.
  ASSERT_EQ(b.residuals.size(), 343u * 41u);
  for (double r : b.residuals) EXPECT_TRUE(std::isfinite(r) && r >= 0);
}

TEST(RealFiles, VendorC3d) {
  GMR_REQUIRE_DATA();
  const auto fp = test::load_marker_file("c3d/fp_type3_2frames.c3d");
  EXPECT_EQ(fp.marker_count(), 34u);
  EXPECT_EQ(fp.frame_count, 2u);
  EXPECT_EQ(fp.frame_rate, 250.0);
  EXPECT_EQ(fp.first_frame, 1166);
  EXPECT_EQ(fp.analog_channels * 4, 64u);  // 64 analog samples per frame at 1000 Hz
  EXPECT_EQ(fp.analog_rate, 1000.0);

  const auto os = test::load_marker_file("c3d/opensim_walking2.c3d");
  EXPECT_EQ(os.marker_count(), 44u);
  EXPECT_EQ(os.frame_count, 1249u);
  EXPECT_EQ(os.frame_rate, 250.0);
  EXPECT_EQ(os.analog_channels * 8, 96u);
  EXPECT_GT(os.missing_points(), 0u);  // gaps are NaN, never zero
  for (std::size_t i = 0; i + 2 < os.positions.size(); i += 3) {
    const bool zero = os.positions[i] == 0 && os.positions[i + 1] == 0 && os.positions[i + 2] == 0;
    ASSERT_FALSE(zero) << "a zero point at value " << i;
  }

  const auto vi = test::load_marker_file("c3d/vicon_markers_analogs.c3d");
  EXPECT_EQ(vi.marker_count(), 51u);
  EXPECT_EQ(vi.frame_count, 580u);
  EXPECT_EQ(vi.frame_rate, 100.0);
  EXPECT_EQ(vi.analog_channels * 20, 760u);
  EXPECT_EQ(vi.names.front().rfind("boite:", 0), 0u);
  EXPECT_TRUE(std::any_of(vi.names.begin(), vi.names.end(), [](const auto& n) { return n.rfind("Daphnee:", 0) == 0; }));
}

TEST(RealFiles, OptotrakShorterThanDeclared) {
  GMR_REQUIRE_DATA();
  // Declares 1149 frames; the stored copy holds 29 whole frames (28,640 bytes).
  Warnings w;
  const auto d = test::load_marker_file("c3d/optotrak.c3d", &w);
  EXPECT_EQ(d.marker_count(), 54u);
  EXPECT_EQ(d.names.front(), "Marker_1");
  EXPECT_EQ(d.names.back(), "Marker_54");
  EXPECT_EQ(d.units, "mm");  // one unit, not the repeated string
  EXPECT_EQ(d.frame_rate, 30.0);
  EXPECT_EQ(d.frame_count, 29u);
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].message.find("at byte 28640: file ends in frame 29 of 1149"), std::string::npos) << w[0].message;
}

TEST(RealFiles, DecFormatLoads) {
  GMR_REQUIRE_DATA();
  // DEC (VAX) floats converted: header and POINT:RATE both read 25 Hz.
  Warnings w;
  const auto d = test::load_marker_file("malformed/ezc3d_read_NOTworking2.c3d", &w);
  EXPECT_TRUE(w.empty());
  EXPECT_EQ(d.marker_count(), 23u);
  EXPECT_EQ(d.frame_count, 670u);
  EXPECT_EQ(d.frame_rate, 25.0);
  EXPECT_EQ(d.first_frame, 0);
  EXPECT_EQ(d.names.front(), "LFHD");
  EXPECT_EQ(d.units, "mm");
  // Integer storage scaled by 0.1449: a head marker about 1.76 m up (Z).
  EXPECT_NEAR(d.positions[2], 1763.0, 1.0);
}

TEST(RealFiles, Cmu0201WaistMatchesBvhRoot) {
  GMR_REQUIRE_DATA();
  const auto c3d = test::load_marker_file("c3d/cmu_02_01.c3d");
  auto bvh = read_bvh(test::data_file("bvh/cmu/02_01.bvh"));
  ASSERT_TRUE(bvh.ok()) << bvh.error().to_string();
  std::vector<Eigen::Vector3d> p(bvh->skeleton.size());
  compute_frame(*bvh, 0, p);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const char* n : {"LFWT", "RFWT", "LBWT", "RBWT"}) {
    const int m = find(c3d, std::string("TakeoMonday:") + n);
    ASSERT_GE(m, 0) << n;
    mean += Eigen::Vector3d(c3d.positions[c3d.index(0, m, 0)], c3d.positions[c3d.index(0, m, 1)],
                            c3d.positions[c3d.index(0, m, 2)]) /
            4.0;
  }
  // BVH (x, y, z) = C3D (y, z, x) x 0.45 / 25.4 (mm to CMU units of 25.4/0.45 mm).
  const double s = 0.45 / 25.4;
  const Eigen::Vector3d mapped(mean.y() * s, mean.z() * s, mean.x() * s);
  // PROVENANCE gives (10.414, 16.714, -30.106) against (10.4194, 16.7048,
  // -30.1003): the root is the waist centre to within 0.01 units (0.6 mm); 0.02
  // units (1.1 mm) allows that and nothing like a swapped axis or a wrong scale.
  EXPECT_NEAR(mapped.x(), 10.414, 0.001);
  EXPECT_NEAR(mapped.y(), 16.714, 0.001);
  EXPECT_NEAR(mapped.z(), -30.106, 0.001);
  EXPECT_LT((mapped - p[0]).cwiseAbs().maxCoeff(), 0.02) << mapped.transpose() << " vs " << p[0].transpose();
}

TEST(RealFiles, OpensimWalking2SameNamesInC3dAndTrc) {
  GMR_REQUIRE_DATA();
  const auto c3d = test::load_marker_file("c3d/opensim_walking2.c3d");
  auto trc = read_trc(test::data_file("trc/opensim_std_walking2_markers.trc"));
  ASSERT_TRUE(trc.ok()) << trc.error().to_string();
  ASSERT_EQ(c3d.names.size(), 44u);
  EXPECT_EQ(c3d.names, trc->names);
}

TEST(Malformed, TruncatedC3d) {
  GMR_REQUIRE_DATA();
  const std::string in_params = test::data_file("malformed/TRUNC_cmu_02_01_in_parameters.c3d").string();
  auto r = read_c3d(in_params);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().file, in_params);
  EXPECT_EQ(r.error().message.rfind("at byte ", 0), 0u) << r.error().message;

  Warnings w;
  auto d = read_c3d(test::data_file("malformed/TRUNC_cmu_02_01_in_data.c3d"), &w);
  ASSERT_TRUE(d.ok()) << d.error().to_string();
  EXPECT_EQ(d->frame_count, (120017u - 6144u) / 656u);  // whole frames present
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].message.find("at byte 120017: file ends in frame 173 of 343"), std::string::npos) << w[0].message;
}

// ---- small files built here

enum class Proc { kIntel = 84, kDec = 85, kMips = 86 };

struct C3dBuilder {
  Proc proc = Proc::kIntel;
  std::string bytes = std::string(512 * 3, '\0');
  std::size_t pos = 512 + 4;

  void u16(std::size_t at, std::uint16_t v) {
    if (proc == Proc::kMips) {
      bytes[at] = static_cast<char>(v >> 8), bytes[at + 1] = static_cast<char>(v & 0xff);
    } else {
      bytes[at] = static_cast<char>(v & 0xff), bytes[at + 1] = static_cast<char>(v >> 8);
    }
  }
  void f32(std::size_t at, float v) {
    if (proc == Proc::kDec) v *= 4;  // VAX F: same bits as IEEE of 4v, words swapped
    const auto bits = std::bit_cast<std::uint32_t>(v);
    if (proc == Proc::kMips) {
      for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>(bits >> (24 - 8 * i));
    } else if (proc == Proc::kDec) {
      bytes[at + 1] = static_cast<char>(bits >> 24), bytes[at] = static_cast<char>(bits >> 16);
      bytes[at + 3] = static_cast<char>(bits >> 8), bytes[at + 2] = static_cast<char>(bits);
    } else {
      for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>(bits >> (8 * i));
    }
  }
  void group(const std::string& name, int id) {
    bytes[pos] = static_cast<char>(name.size());
    bytes[pos + 1] = static_cast<char>(-id);
    bytes.replace(pos + 2, name.size(), name);
    u16(pos + 2 + name.size(), 3);
    pos += 2 + name.size() + 3;
  }
  // A parameter of type `type` with dims; returns where its data starts.
  std::size_t param(const std::string& name, int id, int type, std::vector<int> dims, bool locked = false) {
    std::size_t count = 1;
    for (int d : dims) count *= static_cast<std::size_t>(d);
    const std::size_t data_bytes = count * static_cast<std::size_t>(std::abs(type));
    bytes[pos] = static_cast<char>(locked ? -static_cast<int>(name.size()) : static_cast<int>(name.size()));
    bytes[pos + 1] = static_cast<char>(id);
    bytes.replace(pos + 2, name.size(), name);
    const std::size_t next = pos + 2 + name.size();
    u16(next, static_cast<std::uint16_t>(2 + 2 + dims.size() + data_bytes + 1));
    bytes[next + 2] = static_cast<char>(type);
    bytes[next + 3] = static_cast<char>(dims.size());
    for (std::size_t d = 0; d < dims.size(); ++d) bytes[next + 4 + d] = static_cast<char>(dims[d]);
    const std::size_t data = next + 4 + dims.size();
    pos = data + data_bytes + 1;
    return data;
  }
  // Two points ("A", "B  " padded), two frames, from frame 7; B invalid in frame 1.
  std::string build(float scale) {
    const bool floats = scale < 0;
    bytes[0] = 2;
    bytes[1] = 0x50;
    u16(2, 2);
    u16(6, 7);
    u16(8, 8);
    f32(12, scale);
    u16(16, 3);
    f32(20, 50.0f);
    bytes[512] = 1, bytes[513] = 0x50, bytes[514] = 2, bytes[515] = static_cast<char>(proc);
    group("POINT", 1);
    u16(param("USED", 1, 2, {}), 2);
    u16(param("FRAMES", 1, 2, {}, true), 2);
    f32(param("SCALE", 1, 4, {}), scale);
    f32(param("RATE", 1, 4, {}), 50.0f);
    bytes.replace(param("LABELS", 1, -1, {3, 2}), 6, "A  B  ");
    bytes.replace(param("UNITS", 1, -1, {2}), 2, "mm");
    bytes[pos] = 0;  // end of the records
    const std::size_t size = floats ? 4 : 2;
    std::size_t at = 1024;
    const double values[2][2][3] = {{{1, 2, 3}, {4, 5, 6}}, {{-7, 8.5, 9}, {0, 0, 0}}};
    for (int f = 0; f < 2; ++f) {
      for (int m = 0; m < 2; ++m, at += 4 * size) {
        const bool invalid = f == 1 && m == 1;
        for (int a = 0; a < 3; ++a) {
          if (floats) {
            f32(at + 4 * a, static_cast<float>(values[f][m][a]));
          } else {
            u16(at + 2 * a, static_cast<std::uint16_t>(static_cast<std::int16_t>(values[f][m][a] / scale)));
          }
        }
        const std::int16_t word = invalid ? -1 : static_cast<std::int16_t>(0x0300 | 2);  // cameras 0x03, residual 2
        if (floats)
          f32(at + 12, word);
        else
          u16(at + 6, static_cast<std::uint16_t>(word));
      }
    }
    return bytes;
  }
};

void expect_small_file(const std::string& bytes, double residual_unit) {
  Warnings w;
  auto r = parse_c3d(bytes, "small", &w);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  EXPECT_TRUE(w.empty()) << w.front().to_string();
  EXPECT_EQ(r->names, (std::vector<std::string>{"A", "B"}));
  EXPECT_EQ(r->frame_count, 2u);
  EXPECT_EQ(r->first_frame, 7);
  EXPECT_EQ(r->frame_rate, 50.0);
  EXPECT_EQ(r->units, "mm");
  ASSERT_EQ(r->positions.size(), 12u);
  EXPECT_EQ(std::vector<double>(r->positions.begin(), r->positions.begin() + 9),
            (std::vector<double>{1, 2, 3, 4, 5, 6, -7, 8.5, 9}));
  EXPECT_TRUE(std::isnan(r->positions[9]) && std::isnan(r->positions[10]) && std::isnan(r->positions[11]));
  EXPECT_EQ(r->residuals[0], 2 * residual_unit);
  EXPECT_TRUE(std::isnan(r->residuals[3]));
  EXPECT_EQ(r->missing_points(), 1u);
}

TEST(ProcessorTypes, IntelMipsDecIntegerAndFloat) {
  for (Proc p : {Proc::kIntel, Proc::kMips, Proc::kDec}) {
    SCOPED_TRACE(static_cast<int>(p));
    C3dBuilder a;
    a.proc = p;
    expect_small_file(a.build(-0.5f), 0.5);  // float storage; |scale| scales residuals
    C3dBuilder b;
    b.proc = p;
    expect_small_file(b.build(0.5f), 0.5);  // int16 storage x 0.5
  }
}

TEST(Malformed, FramesWithoutMarkersAreCapped) {
  // A 1.5 KB file without markers or analog whose TRIAL fields declare
  // `last` frames (its header's 16-bit last frame overflowed): no bytes back
  // those frames, so their count is capped (gmr/core/limits.h). It once
  // declared 2^28 and a conversion to TRC ended in std::bad_alloc.
  const auto build = [](std::uint32_t last) {
    C3dBuilder b;
    b.bytes[0] = 2;
    b.bytes[1] = 0x50;
    b.u16(2, 0);  // no points
    b.u16(6, 1);
    b.u16(8, 65535);
    b.f32(12, -1.0f);
    b.u16(16, 3);
    b.f32(20, 50.0f);
    b.bytes[512] = 1, b.bytes[513] = 0x50, b.bytes[514] = 2, b.bytes[515] = static_cast<char>(b.proc);
    b.group("POINT", 1);
    b.u16(b.param("USED", 1, 2, {}), 0);
    b.f32(b.param("RATE", 1, 4, {}), 50.0f);
    b.group("TRIAL", 2);
    const std::size_t s = b.param("ACTUAL_START_FIELD", 2, 2, {2});
    b.u16(s, 1);
    b.u16(s + 2, 0);
    const std::size_t e = b.param("ACTUAL_END_FIELD", 2, 2, {2});
    b.u16(e, static_cast<std::uint16_t>(last & 0xffff));
    b.u16(e + 2, static_cast<std::uint16_t>(last >> 16));
    b.bytes[b.pos] = 0;
    return b.bytes;
  };
  auto ok = parse_c3d(build(1u << 20), "x.c3d");
  ASSERT_TRUE(ok.ok()) << ok.error().to_string();
  EXPECT_EQ(ok->frame_count, 1u << 20);
  EXPECT_TRUE(ok->positions.empty());
  for (std::uint32_t last : {(1u << 20) + 1, 1u << 28}) {
    auto r = parse_c3d(build(last), "x.c3d");
    ASSERT_FALSE(r.ok()) << last;
    EXPECT_NE(r.error().to_string().find("x.c3d: at byte 8: frame count " + std::to_string(last) +
                                         " is above gmr's limit of "),
              std::string::npos)
        << r.error().to_string();
  }
}

TEST(Malformed, SmallC3dErrorsAreLocated) {
  const std::string good = C3dBuilder().build(-1.0f);
  const auto error_of = [](std::string bytes) {
    auto r = parse_c3d(bytes, "x.c3d");
    return r.ok() ? std::string("ok") : r.error().to_string();
  };
  EXPECT_EQ(error_of(""), "x.c3d: at byte 0: file too short for a C3D header (0 of 512 bytes)");
  std::string s = good;
  s[1] = 0x51;
  EXPECT_EQ(error_of(s), "x.c3d: at byte 1: not a C3D file (byte 2 is 81, expected 80)");
  s = good;
  s[515] = 99;
  EXPECT_EQ(error_of(s), "x.c3d: at byte 515: unknown processor type 99 (expected 84 Intel, 85 DEC or 86 MIPS)");
  s = good;
  s[0] = 9;
  EXPECT_NE(error_of(s).find("at byte 0: parameter section at block 9"), std::string::npos) << error_of(s);
  // Data start inside the parameters (header and parameter both say block 2).
  s = good;
  s[16] = 2;
  EXPECT_NE(error_of(s).find("at byte 16: data section (block 2) starts before the end of the parameter section"),
            std::string::npos)
      << error_of(s);
}

}  // namespace
}  // namespace gmr
