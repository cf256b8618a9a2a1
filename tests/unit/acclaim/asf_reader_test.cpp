// ASF reader: every ASF/AMC item of FORMAT-PITFALLS.md that concerns the
// skeleton file, the CMU files of the corpus, and broken input.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "acclaim_test_util.h"
#include "gmr/core/file_util.h"

namespace gmr::test {
namespace {

std::string replace_all(std::string s, const std::string& from, const std::string& to) {
  for (std::size_t p = s.find(from); p != std::string::npos; p = s.find(from, p + to.size()))
    s.replace(p, from.size(), to);
  return s;
}

// FK of the small skeleton for its AMC values, to compare variants of the text.
std::vector<Eigen::Vector3d> small_positions(const std::string& asf, const std::string& amc = kSmallAmc) {
  const AsfSkeleton s = must_parse_asf(asf);
  const AmcMotion m = must_parse_amc(amc, s);
  return acclaim_positions(s, m);
}

void expect_same_positions(const std::vector<Eigen::Vector3d>& a, const std::vector<Eigen::Vector3d>& b,
                           double tol = 0) {
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_LE((a[i] - b[i]).norm(), tol) << "position " << i;
}

TEST(ReadsCmuFile, Asf) {
  GMR_REQUIRE_DATA();
  Warnings w;
  auto r = read_asf(data_file("asfamc/01/01.asf"), &w);
  ASSERT_TRUE(r.ok()) << r.error().to_string();
  const AsfSkeleton& s = *r;
  EXPECT_EQ(s.version, "1.10");
  EXPECT_EQ(s.name, "VICON");
  EXPECT_EQ(s.units.length, 0.45);
  EXPECT_TRUE(s.units.degrees);
  ASSERT_EQ(s.bones.size(), 31u);  // root + 30 bones
  EXPECT_EQ(s.bones[0].name, "root");
  EXPECT_EQ(s.bones[0].dofs.size(), 6u);
  EXPECT_EQ(s.value_count(), 62);  // CMU: 62 AMC values per frame
  const AsfBone& lfoot = s.bones[static_cast<std::size_t>(s.find("lfoot"))];
  EXPECT_EQ(lfoot.axis.x(), -90.0);
  EXPECT_EQ(lfoot.axis.y(), 7.62852e-016);  // three-digit exponent
  ASSERT_EQ(lfoot.dofs.size(), 2u);
  EXPECT_EQ(lfoot.dofs[0], AcclaimDof::kRx);
  EXPECT_EQ(lfoot.dofs[1], AcclaimDof::kRz);
  ASSERT_EQ(lfoot.limits.size(), 2u);  // limits spanning two lines
  EXPECT_EQ(lfoot.limits[1].min, -70.0);
  EXPECT_EQ(lfoot.limits[1].max, 20.0);
  EXPECT_TRUE(s.bones[static_cast<std::size_t>(s.find("lhipjoint"))].dofs.empty());
  // Depth-first order: every parent before its children.
  for (std::size_t b = 1; b < s.bones.size(); ++b) EXPECT_LT(s.bones[b].parent, static_cast<int>(b));
  EXPECT_EQ(s.bones[static_cast<std::size_t>(s.find("thorax"))].parent, s.find("upperback"));
  EXPECT_TRUE(w.empty()) << w.front().to_string();
}

TEST(ReadsEveryCorpusSkeleton, Asf) {
  GMR_REQUIRE_DATA();
  const auto files = data_files("asfamc", ".asf");
  ASSERT_GE(files.size(), 6u);
  for (const auto& f : files) {
    auto r = read_asf(f);
    ASSERT_TRUE(r.ok()) << r.error().to_string();
    EXPECT_EQ(r->bones.size(), 31u) << f;
  }
}

// Pitfall 1: `,` `(` `)` are whitespace, `#` starts a comment (also mid-line).
TEST(SeparatorsAndComments, Asf) {
  std::string t = kSmallAsf;
  t = replace_all(t, "direction 0.34202 -0.939693 0", "direction (0.34202,-0.939693,0)  # unit vector");
  t = replace_all(t, "order TX TY TZ RX RY RZ", "order TX,TY,TZ,RX,RY,RZ");
  t = "# a comment line\n" + replace_all(t, ":bonedata", "# before bonedata\n:bonedata # trailing");
  expect_same_positions(small_positions(t), small_positions(kSmallAsf));
}

// Pitfall 1: limits span lines, may use inf, and pair up with the dofs.
TEST(LimitsSpanLines, Asf) {
  std::string t = replace_all(kSmallAsf, "limits (-160.0 20.0)\n            (-70.0 70.0)\n            (-60.0 70.0)",
                              "limits (-inf 20.0) (-70.0\n 70.0)\n\t(-60.0 inf)");
  const AsfSkeleton s = must_parse_asf(t);
  const AsfBone& hip = s.bones[static_cast<std::size_t>(s.find("hip"))];
  ASSERT_EQ(hip.limits.size(), 3u);
  EXPECT_TRUE(std::isinf(hip.limits[0].min) && hip.limits[0].min < 0);
  EXPECT_EQ(hip.limits[1].max, 70.0);
  EXPECT_TRUE(std::isinf(hip.limits[2].max));
  EXPECT_EQ(hip.dofs.size(), 3u);
}

// Pitfall 1: three-digit exponents as CMU writes them.
TEST(ThreeDigitExponents, Asf) {
  const std::string t = replace_all(kSmallAsf, "direction 0 1 0", "direction 1.53601e-011 1e+000 -4.2E-011");
  const AsfSkeleton s = must_parse_asf(t);
  const AsfBone& back = s.bones[static_cast<std::size_t>(s.find("back"))];
  EXPECT_EQ(back.direction.x(), 1.53601e-11);
  EXPECT_EQ(back.direction.y(), 1.0);
  EXPECT_EQ(back.direction.z(), -4.2e-11);
}

// Pitfall 2: field order inside a bone and section order are not fixed.
TEST(FieldOrderNotHardCoded, Asf) {
  const std::string shuffled = R"(:name small
:root
   orientation 0 0 0
   position 0 0 0
   axis XYZ
   order TX TY TZ RX RY RZ
:units
  angle deg
  length 0.45
:bonedata
  begin
     limits (-10.0 170.0)
     dof rx
     axis 0 0 20 XYZ
     length 7.0
     direction 0.34202 -0.939693 0
     name knee
     id 2
  end
  begin
     dof rx ry rz
     name hip
     length 7.5
     direction 0.34202 -0.939693 0
     axis 0 0 20 XYZ
  end
  begin
     name back
     axis 0 0 0 XYZ
     dof rz rx
     direction 0 1 0
     length 2
  end
:hierarchy
  begin
    hip knee
    root hip back
  end
)";
  expect_same_positions(small_positions(shuffled), small_positions(kSmallAsf));
}

// Pitfall 2: the axis order token is read, not assumed to be XYZ.
TEST(AxisOrderIsRead, Asf) {
  // XYZ applies x first (C = Rz Ry Rx); ZYX applies z first (C = Rx Ry Rz).
  const std::string xyz =
      replace_all(kSmallAsf, "axis 0 0 20 XYZ\n     dof rx ry rz", "axis 30 -40 20 XYZ\n     dof rx ry rz");
  const std::string zyx =
      replace_all(kSmallAsf, "axis 0 0 20 XYZ\n     dof rx ry rz", "axis 30 -40 20 ZYX\n     dof rx ry rz");
  const AsfSkeleton a = must_parse_asf(xyz);
  const AsfSkeleton b = must_parse_asf(zyx);
  const AmcMotion m = must_parse_amc(kSmallAmc, a);
  const int hip = a.find("hip");
  const Eigen::Matrix3d ca = (Eigen::AngleAxisd(20 * M_PI / 180, Eigen::Vector3d::UnitZ()) *
                              Eigen::AngleAxisd(-40 * M_PI / 180, Eigen::Vector3d::UnitY()) *
                              Eigen::AngleAxisd(30 * M_PI / 180, Eigen::Vector3d::UnitX()))
                                 .toRotationMatrix();
  const Eigen::Matrix3d cb = (Eigen::AngleAxisd(30 * M_PI / 180, Eigen::Vector3d::UnitX()) *
                              Eigen::AngleAxisd(-40 * M_PI / 180, Eigen::Vector3d::UnitY()) *
                              Eigen::AngleAxisd(20 * M_PI / 180, Eigen::Vector3d::UnitZ()))
                                 .toRotationMatrix();
  // hip values in frame 0: rx 5, ry -10, rz 15 -> M = Rz(15) Ry(-10) Rx(5).
  const Eigen::Matrix3d mm = (Eigen::AngleAxisd(15 * M_PI / 180, Eigen::Vector3d::UnitZ()) *
                              Eigen::AngleAxisd(-10 * M_PI / 180, Eigen::Vector3d::UnitY()) *
                              Eigen::AngleAxisd(5 * M_PI / 180, Eigen::Vector3d::UnitX()))
                                 .toRotationMatrix();
  EXPECT_TRUE(acclaim_local_rotation(a, m, 0, hip).isApprox(ca * mm * ca.transpose(), 1e-12));
  EXPECT_TRUE(acclaim_local_rotation(b, m, 0, hip).isApprox(cb * mm * cb.transpose(), 1e-12));
}

// Pitfall 2: CRLF, CR-only line ends and tabs.
TEST(LineEndsAndTabs, Asf) {
  const auto ref = small_positions(kSmallAsf);
  expect_same_positions(small_positions(replace_all(kSmallAsf, "\n", "\r\n"), replace_all(kSmallAmc, "\n", "\r\n")),
                        ref);
  expect_same_positions(small_positions(replace_all(kSmallAsf, "\n", "\r"), replace_all(kSmallAmc, "\n", "\r")), ref);
  expect_same_positions(small_positions(replace_all(kSmallAsf, " ", "\t"), replace_all(kSmallAmc, " ", "\t")), ref);
}

// Pitfall 3: bone names are case-insensitive (hierarchy and AMC), and kept as written.
TEST(CaseInsensitiveNames, Asf) {
  std::string t = replace_all(kSmallAsf, "name hip", "name LeftHip");
  t = replace_all(t, "root hip back", "ROOT lefthip BACK");
  t = replace_all(t, "hip knee", "LEFTHIP Knee");
  const AsfSkeleton s = must_parse_asf(t);
  EXPECT_EQ(s.find("lefthip"), s.find("LEFTHIP"));
  EXPECT_EQ(s.bones[static_cast<std::size_t>(s.find("lefthip"))].name, "LeftHip");
  const std::string amc = replace_all(replace_all(kSmallAmc, "hip ", "lEfThIp "), "root ", "ROOT ");
  expect_same_positions(acclaim_positions(s, must_parse_amc(amc, s)), small_positions(kSmallAsf));

  // Two bones whose names differ only in case are the same name.
  auto dup = parse_asf(replace_all(kSmallAsf, "name back", "name HIP"), "dup.asf");
  ASSERT_FALSE(dup.ok());
  EXPECT_NE(dup.error().message.find("repeats"), std::string::npos) << dup.error().to_string();
  EXPECT_EQ(dup.error().line, 35);
  EXPECT_EQ(dup.error().column, 11);
}

// Pitfall 4: `length` is recorded (not applied); `angle rad` makes axis angles radians,
// and the AMC's own :DEGREES/:RADIANS governs its values.
TEST(UnitsLengthAndAngle, Asf) {
  const auto ref = small_positions(kSmallAsf);
  const AsfSkeleton deg = must_parse_asf(kSmallAsf);
  EXPECT_EQ(deg.units.length, 0.45);
  EXPECT_EQ(deg.units.mass, 1.0);

  const double r20 = 20.0 * M_PI / 180.0;
  std::string rad = replace_all(kSmallAsf, "angle deg", "angle rad");
  rad = replace_all(rad, "axis 0 0 20 XYZ", "axis 0 0 " + format_double(r20) + " XYZ");
  // No :DEGREES line: the AMC follows the ASF's unit (radians here).
  std::string amc_rad = replace_all(kSmallAmc, ":DEGREES\n", "");
  const AsfSkeleton s = must_parse_asf(rad);
  EXPECT_FALSE(s.units.degrees);
  const AmcMotion m_rad_default = must_parse_amc(amc_rad, s);
  EXPECT_FALSE(m_rad_default.degrees);
  // With :DEGREES the AMC values stay degrees whatever the ASF says.
  expect_same_positions(acclaim_positions(s, must_parse_amc(kSmallAmc, s)), ref, 1e-12);
  // The same motion written in radians.
  const AmcMotion m = must_parse_amc(kSmallAmc, deg);
  AmcMotion converted = m;
  for (std::size_t f = 0; f < m.frame_count; ++f) {
    for (int b = 0; b < static_cast<int>(deg.bones.size()); ++b) {
      const auto& bone = deg.bones[static_cast<std::size_t>(b)];
      for (std::size_t d = 0; d < bone.dofs.size(); ++d) {
        const std::size_t k =
            f * static_cast<std::size_t>(deg.value_count()) + static_cast<std::size_t>(deg.value_offset(b)) + d;
        if (bone.dofs[d] <= AcclaimDof::kRz) converted.values[k] *= M_PI / 180.0;
      }
    }
  }
  converted.degrees = false;
  expect_same_positions(acclaim_positions(deg, converted), ref, 1e-12);
  auto text = format_amc(deg, converted);
  ASSERT_TRUE(text.ok());
  EXPECT_NE(text->find(":RADIANS"), std::string::npos);
  expect_same_positions(acclaim_positions(deg, must_parse_amc(*text, deg)), ref, 1e-12);
}

// Pitfall 5: the root `order` sets the AMC value order of the root.
TEST(RootOrder, Asf) {
  const std::string t = replace_all(kSmallAsf, "order TX TY TZ RX RY RZ", "order RZ RY RX TZ TY TX");
  const AsfSkeleton s = must_parse_asf(t);
  // Frame 0 root: TX 1 TY 2 TZ 3 RX 10 RY 20 RZ 30 in the reference, reordered here.
  std::string amc = replace_all(kSmallAmc, "root 1 2 3 10 20 30", "root 30 20 10 3 2 1");
  amc = replace_all(amc, "root 1.5 2.5 3.5 -10 5 0", "root 0 5 -10 3.5 2.5 1.5");
  // The listed rotation order (RZ first) changes M: M = Rx(10) Ry(20) Rz(30) now.
  const AmcMotion m = must_parse_amc(amc, s);
  const auto p = acclaim_positions(s, m);
  EXPECT_EQ(p[0], Eigen::Vector3d(1, 2, 3));
  const Eigen::Matrix3d expect = (Eigen::AngleAxisd(10 * M_PI / 180, Eigen::Vector3d::UnitX()) *
                                  Eigen::AngleAxisd(20 * M_PI / 180, Eigen::Vector3d::UnitY()) *
                                  Eigen::AngleAxisd(30 * M_PI / 180, Eigen::Vector3d::UnitZ()))
                                     .toRotationMatrix();
  EXPECT_TRUE(acclaim_local_rotation(s, m, 0, 0).isApprox(expect, 1e-12));
  // Positions of the back bone (dof rz rx, axis 0) follow directly.
  const Eigen::Matrix3d back = (Eigen::AngleAxisd(-3 * M_PI / 180, Eigen::Vector3d::UnitX()) *
                                Eigen::AngleAxisd(7 * M_PI / 180, Eigen::Vector3d::UnitZ()))
                                   .toRotationMatrix();
  const int b = s.find("back");
  EXPECT_LE(
      (p[static_cast<std::size_t>(b)] - (Eigen::Vector3d(1, 2, 3) + expect * back * Eigen::Vector3d(0, 2, 0))).norm(),
      1e-12);
}

// Pitfall 6: dof subsets, translations and `l`; bones without dof are absent from the AMC.
TEST(DofSubsetsWithTranslationAndLength, Asf) {
  std::string t = replace_all(kSmallAsf, "dof rz rx", "dof tx ty tz l ry");
  const AsfSkeleton s = must_parse_asf(t);
  const int b = s.find("back");
  ASSERT_EQ(s.bones[static_cast<std::size_t>(b)].dofs.size(), 5u);
  std::string amc = replace_all(kSmallAmc, "back 7 -3", "back 0.5 -0.25 1 3 90");
  amc = replace_all(amc, "back -7 3", "back 0 0 0 0 0");
  const AmcMotion m = must_parse_amc(amc, s);
  const auto p = acclaim_positions(s, m);
  const std::size_t n = s.bones.size();
  // Frame 0: back = root + W_root * ((0.5, -0.25, 1) + Ry(90) * (0, 2 + 3, 0)); Ry leaves y alone.
  const Eigen::Matrix3d wr = acclaim_local_rotation(s, m, 0, 0);
  EXPECT_LE((p[static_cast<std::size_t>(b)] - (p[0] + wr * Eigen::Vector3d(0.5, 4.75, 1))).norm(), 1e-12);
  // Frame 1: rest offset.
  const Eigen::Matrix3d wr1 = acclaim_local_rotation(s, m, 1, 0);
  EXPECT_LE((p[n + static_cast<std::size_t>(b)] - (p[n] + wr1 * Eigen::Vector3d(0, 2, 0))).norm(), 1e-12);
  // A bone with no dof takes no AMC line.
  const std::string no_dof = replace_all(kSmallAsf, "     dof rz rx\n", "");
  const AsfSkeleton s2 = must_parse_asf(no_dof);
  EXPECT_EQ(s2.value_count(), 6 + 3 + 1);
  auto r = parse_amc(kSmallAmc, "nodof.amc", s2);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().line, 7);
  EXPECT_NE(r.error().message.find("expected 0 values"), std::string::npos) << r.error().to_string();
}

// Pitfall 7: limits never create dofs.
TEST(NoDofInferredFromLimits, Asf) {
  const std::string t = replace_all(kSmallAsf, "     dof rx\n     limits (-10.0 170.0)", "     limits (-10.0 170.0)");
  Warnings w;
  const AsfSkeleton s = must_parse_asf(t, &w);
  const AsfBone& knee = s.bones[static_cast<std::size_t>(s.find("knee"))];
  EXPECT_TRUE(knee.dofs.empty());
  EXPECT_TRUE(knee.limits.empty());
  ASSERT_EQ(w.size(), 1u);
  EXPECT_NE(w[0].message.find("no dof"), std::string::npos);
  // The AMC must then not list values for it.
  auto r = parse_amc(kSmallAmc, "m.amc", s);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().line, 6);
}

struct BrokenAsf {
  const char* what;
  std::string from, to;  // edit applied to kSmallAsf
  int line, column;
  const char* message;  // substring of the error message
};

TEST(BrokenInputGivesLineAndColumn, Asf) {
  const std::vector<BrokenAsf> cases = {
      {"fused numbers", "direction 0 1 0", "direction 0.0-7.5 1 0", 36, 16, "expected a number after 'direction'"},
      {"missing number", "length 7.0", "length", 28, 12, "expected 1 number after 'length'"},
      {"unknown dof", "dof rz rx", "dof rz rw", 39, 13, "expected rx, ry, rz, tx, ty, tz or l"},
      {"repeated dof", "dof rz rx", "dof rz rz", 39, 13, "listed twice"},
      {"bad axis order", "axis 0 0 0 XYZ", "axis 0 0 0 XYX", 38, 17, "rotation order"},
      {"bad root order", "order TX TY TZ RX RY RZ", "order TX TY TZ RX RY L", 8, 25, "root order"},
      {"bad angle unit", "angle deg", "angle grad", 6, 9, "'deg' or 'rad'"},
      {"limits count", "limits (-10.0 170.0)", "limits (-10.0 170.0) (0 1)", 31, 6, "expected 1 limit pairs"},
      {"odd limits", "limits (-10.0 170.0)", "limits (-10.0 170.0 3)", 31, 6, "pairs of limits"},
      {"unknown parent", "hip knee", "hap knee", 44, 5, "unknown bone 'hap'"},
      {"unknown child", "hip knee", "hip kneee", 44, 9, "unknown bone 'kneee'"},
      {"two parents", "hip knee", "hip knee\n    back knee", 45, 10, "already has a parent"},
      {"not connected", "hip knee\n", "", 24, 1, "'knee' is not connected"},
      {"cycle", "root hip back\n    hip knee", "root back\n    hip knee\n    knee hip", 13, 1,
       "'hip' is not connected"},
      {"no name", "     name knee\n", "", 31, 3, "expected a 'name'"},
      {"no length", "     length 2\n", "", 39, 3, "expected a 'length'"},
      {"offset overflows", "direction 0 1 0\n     length 2", "direction 0 1e10 0\n     length 1e300", 37, 13,
       "bone 'back': direction times length is not finite"},
      {"bone named root", "name back", "name Root", 35, 11, "may not be named"},
      {"bone named end", "name back", "name END", 35, 11, "a keyword of the hierarchy"},
      {"text before sections", ":version 1.10", "hello\n:version 1.10", 1, 1, "expected a section keyword"},
      {"begin missing", "  begin\n     id 3", "     id 3", 33, 6, "expected 'begin'"},
      {"end missing", "  end\n:hierarchy", ":hierarchy", 40, 1, "expected 'end' to close the bone"},
      {"hierarchy unterminated", ":hierarchy", ":hierarchy", 44, 1, "file ends inside :hierarchy"},
      {"no root", ":root\n", ":ruut\n", 45, 1, "expected a :root section"},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.what);
    std::string t = kSmallAsf;
    const auto p = t.find(c.from);
    ASSERT_NE(p, std::string::npos) << c.from;
    t.replace(p, c.from.size(), c.to);
    if (std::string(c.what) == "hierarchy unterminated") t = t.substr(0, t.rfind("  end"));
    auto r = parse_asf(t, "bad.asf");
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.error().file, "bad.asf");
    EXPECT_EQ(r.error().line, c.line) << r.error().to_string();
    EXPECT_EQ(r.error().column, c.column) << r.error().to_string();
    EXPECT_NE(r.error().message.find(c.message), std::string::npos) << r.error().to_string();
  }
}

TEST(TruncatedCorpusFile, Asf) {
  GMR_REQUIRE_DATA();
  const auto path = data_file("malformed/TRUNC_07-walk_in_bonedata.asf");
  auto r = read_asf(path);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().file, path.string());
  EXPECT_EQ(r.error().line, 147);
  EXPECT_EQ(r.error().column, 12);
  EXPECT_NE(r.error().message.find("expected 1 number after 'length'"), std::string::npos) << r.error().to_string();
}

// Every prefix of a real file parses or fails with a located error; none crashes.
TEST(EveryPrefixOfARealFile, Asf) {
  GMR_REQUIRE_DATA();
  auto text = read_file(data_file("asfamc/01/01.asf"));
  ASSERT_TRUE(text.ok());
  int ok = 0;
  std::vector<std::size_t> cuts;
  for (std::size_t n = 0; n < text->size(); n += kSanitized ? 5 : 1) cuts.push_back(n);
  cuts.push_back(text->size());
  for (const std::size_t n : cuts) {
    auto r = parse_asf(std::string_view(*text).substr(0, n), "prefix.asf");
    if (r.ok()) {
      ++ok;
      continue;
    }
    EXPECT_GT(r.error().line, 0) << n;
    EXPECT_GT(r.error().column, 0) << n;
  }
  EXPECT_GE(ok, 1);  // at least the whole file
}

TEST(UnknownSectionsAndFieldsWarn, Asf) {
  std::string t = replace_all(kSmallAsf, ":bonedata", ":skin foo.skin\n  whatever 1 2\n:bonedata");
  t = replace_all(t, "     id 3", "     id 3\n     bodymass 2\n     colour red");
  Warnings w;
  const AsfSkeleton s = must_parse_asf(t, &w);
  EXPECT_EQ(s.bones.size(), 4u);
  ASSERT_EQ(w.size(), 2u);
  EXPECT_NE(w[0].message.find(":skin"), std::string::npos);
  EXPECT_NE(w[1].message.find("colour"), std::string::npos);
}

}  // namespace
}  // namespace gmr::test
