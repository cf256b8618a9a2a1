// Acclaim -> GMR and GMR -> Acclaim: positions agree in every frame.
#include <gtest/gtest.h>

#include <unistd.h>

#include <random>
#include <string>

#include "acclaim_test_util.h"
#include "gmr/ops/convert.h"
#include "gmr/io/bvh.h"
#include "gmr/core/file_util.h"
#include "gmr/io/motion_file.h"

namespace gmr::test {
namespace {

// Every ASF/AMC pair of the corpus: positions from the Acclaim model and from
// its GMR conversion agree in every frame within 1e-9 of the skeleton size.
TEST(EveryCorpusPairMatchesItsGmrConversion, AcclaimToGmr) {
  GMR_REQUIRE_DATA();
  const auto pairs = acclaim_pairs();
  ASSERT_GE(pairs.size(), 9u);
  for (const auto& [asf, amc] : pairs) {
    SCOPED_TRACE(amc.string());
    auto s = read_asf(asf);
    ASSERT_TRUE(s.ok()) << s.error().to_string();
    auto m = read_amc(amc, *s);
    ASSERT_TRUE(m.ok()) << m.error().to_string();
    const std::size_t frames = m->frame_count;
    limit_frames(*m, *s);
    auto g = acclaim_to_gmr(*s, *m);
    ASSERT_TRUE(g.ok()) << g.error().to_string();
    ASSERT_TRUE(g->validate().ok());
    EXPECT_GT(frames, 100u);
    EXPECT_EQ(g->convention, Convention::kPreRotation);
    EXPECT_EQ(g->frame_count, m->frame_count);
    EXPECT_DOUBLE_EQ(g->frame_time, 1.0 / 120.0);
    ASSERT_EQ(g->skeleton.size(), s->bones.size());
    EXPECT_EQ(g->skeleton.joint(0).name, "root");
    for (std::size_t b = 1; b < s->bones.size(); ++b)
      EXPECT_EQ(g->skeleton.joint(static_cast<int>(b)).name, s->bones[b].name);
    const double size = skeleton_size(*g);
    EXPECT_GT(size, 10.0);  // CMU units: a person is ~30 units tall
    const auto a = acclaim_positions(*s, *m);
    const auto p = compute_positions(*g);
    EXPECT_POSITIONS_NEAR(g->skeleton, a, p, 1e-9 * size);
  }
}

// read_asf_amc is what load_motion uses for .amc input.
TEST(ReadAsfAmcConverts, AcclaimToGmr) {
  GMR_REQUIRE_DATA();
  auto g = read_asf_amc(data_file("asfamc/09/09-run.asf"), data_file("asfamc/09/09_06-run.amc"));
  ASSERT_TRUE(g.ok()) << g.error().to_string();
  EXPECT_EQ(g->frame_count, 141u);
  EXPECT_EQ(g->skeleton.size(), 31u);
  // lhipjoint has no dof: no channels. ltibia has axis != 0: three ZYX channels.
  // lowerback has axis 0: its own dofs, reversed (rx ry rz -> Zrotation Yrotation Xrotation).
  const Skeleton& sk = g->skeleton;
  EXPECT_TRUE(sk.joint(sk.find("lhipjoint")).channels.empty());
  EXPECT_EQ(sk.joint(sk.find("ltibia")).channels,
            (std::vector<ChannelType>{ChannelType::kZrotation, ChannelType::kYrotation, ChannelType::kXrotation}));
  EXPECT_EQ(sk.joint(sk.find("lclavicle")).channels,  // dof ry rz, axis 0
            (std::vector<ChannelType>{ChannelType::kZrotation, ChannelType::kYrotation}));
  EXPECT_EQ(sk.joint(0).channels.size(), 6u);
  auto missing = read_asf_amc(data_file("asfamc/09/09-run.asf"), data_file("asfamc/09/no_such.amc"));
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().to_string().find("no_such.amc"), std::string::npos);
}

// Units: offsets are direction * length in file units unless a scale is asked for.
TEST(LengthScale, AcclaimToGmr) {
  const AsfSkeleton s = must_parse_asf(kSmallAsf);
  const AmcMotion m = must_parse_amc(kSmallAmc, s);
  AcclaimToGmrOptions metres;
  metres.length_scale = (1.0 / 0.45) * 2.54 / 100.0;  // CMU: units -> inches -> metres
  metres.frame_time = 0.5;
  auto g = acclaim_to_gmr(s, m, metres);
  ASSERT_TRUE(g.ok());
  EXPECT_EQ(g->frame_time, 0.5);
  const auto a = acclaim_positions(s, m);
  const auto p = compute_positions(*g);
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_LE((a[i] * metres.length_scale - p[i]).norm(), 1e-12);
  const AsfBone& hip = s.bones[static_cast<std::size_t>(s.find("hip"))];
  EXPECT_EQ(g->skeleton.joint(s.find("hip")).offset, hip.direction * (hip.length * metres.length_scale));
}

// Random values on skeletons using every feature: non-zero root orientation and
// position, axis orders other than XYZ, dof subsets in odd orders, translations
// and `l`, radians. Positions agree to round-off in every frame.
TEST(EveryFeatureMatches, AcclaimToGmr) {
  const std::string asf = R"(:units
  angle rad
:root
   order RZ TX RX TZ RY TY
   axis ZXY
   position 1 -2 3
   orientation 0.3 -0.2 0.1
:bonedata
  begin
     name a
     direction 0.6 0.8 0
     length 3
     axis 0.5 0.1 -0.7 YZX
     dof rz rx ry
  end
  begin
     name b
     direction 0 0 1
     length 2
     axis 0.2 0 0 XYZ
     dof ty l rx tz tx
  end
  begin
     name c
     direction 1 0 0
     length 1
     axis 0 0 0 XYZ
     dof ry rx
  end
  begin
     name d
     direction 0 1 0
     length 1.5
     axis 0 0 0 XYZ
     dof l
  end
:hierarchy
  begin
    root a c
    a b
    c d
  end
)";
  const AsfSkeleton s = must_parse_asf(asf);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  AmcMotion m;
  m.degrees = false;
  m.frame_count = 200;
  m.values.resize(m.frame_count * static_cast<std::size_t>(s.value_count()));
  for (double& v : m.values) v = u(rng);
  auto g = acclaim_to_gmr(s, m);
  ASSERT_TRUE(g.ok()) << g.error().to_string();
  EXPECT_LE(acclaim_gmr_max_error(s, m, *g), 1e-12);
  // b has translations: three position channels before its rotation channels.
  EXPECT_EQ(g->skeleton.joint(s.find("b")).channels.size(), 6u);
  // And back: GMR -> Acclaim -> positions.
  auto back = gmr_to_acclaim(*g);
  ASSERT_TRUE(back.ok()) << back.error().to_string();
  const auto a = acclaim_positions(s, m);
  const auto p = acclaim_positions(back->skeleton, back->motion);
  ASSERT_EQ(a.size(), p.size());
  double worst = 0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, (a[i] - p[i]).norm());
  EXPECT_LE(worst, 1e-12);
}

// Euler angles stay continuous across frames (no 360-degree jumps) where the
// rotation moves smoothly.
TEST(DecomposedAnglesAreContinuous, AcclaimToGmr) {
  GMR_REQUIRE_DATA();
  auto s = read_asf(data_file("asfamc/11/11.asf"));
  ASSERT_TRUE(s.ok());
  auto m = read_amc(data_file("asfamc/11/11_01.amc"), *s);
  ASSERT_TRUE(m.ok());
  auto g = acclaim_to_gmr(*s, *m);
  ASSERT_TRUE(g.ok());
  for (std::size_t f = 1; f < g->frame_count; ++f) {
    const auto a = g->frame(f - 1);
    const auto b = g->frame(f);
    for (std::size_t c = 0; c < a.size(); ++c)
      EXPECT_LT(std::abs(a[c] - b[c]), 90.0) << "frame " << f << " channel " << c;
  }
}

// GMR -> Acclaim on every corpus pair (Acclaim -> GMR -> Acclaim): same positions.
TEST(CorpusRoundTripThroughGmr, GmrToAcclaim) {
  GMR_REQUIRE_DATA();
  for (const auto& [asf, amc] : acclaim_pairs()) {
    SCOPED_TRACE(amc.string());
    auto s = read_asf(asf);
    ASSERT_TRUE(s.ok());
    auto m = read_amc(amc, *s);
    ASSERT_TRUE(m.ok());
    limit_frames(*m, *s);
    auto g = acclaim_to_gmr(*s, *m);
    ASSERT_TRUE(g.ok());
    auto back = gmr_to_acclaim(*g);
    ASSERT_TRUE(back.ok()) << back.error().to_string();
    // Same depth-first order, same names: bone b <-> bone b.
    ASSERT_EQ(back->skeleton.bones.size(), s->bones.size());
    for (std::size_t b = 0; b < s->bones.size(); ++b) EXPECT_EQ(back->skeleton.bones[b].name, s->bones[b].name);
    const auto a = acclaim_positions(*s, *m);
    const auto p = acclaim_positions(back->skeleton, back->motion);
    EXPECT_POSITIONS_NEAR(g->skeleton, a, p, 1e-9 * skeleton_size(*g));
  }
}

Motion two_joint_motion(Convention convention) {
  Joint root{"Hips",
             kNoParent,
             kNoParent,
             Eigen::Vector3d(0, 1, 0),
             {ChannelType::kXposition, ChannelType::kYposition, ChannelType::kZposition, ChannelType::kZrotation,
              ChannelType::kXrotation, ChannelType::kYrotation}};
  Joint spine{"Spine",
              0,
              kNoParent,
              Eigen::Vector3d(0, 2, 0),
              {ChannelType::kYposition, ChannelType::kXrotation, ChannelType::kZrotation}};
  Joint end{"Spine_End", 1, kNoParent, Eigen::Vector3d(0, 0, 0), {}};
  Motion m;
  m.skeleton = *Skeleton::create({root, spine, end});
  m.convention = convention;
  m.frame_time = 1.0 / 30.0;
  m.frame_count = 3;
  m.values = {0, 1,   0, 10,  20,  30, 2.5, 5,  6,    //
              1, 1,   1, -10, 0,   30, 3,   45, -45,  //
              2, 0.5, 3, 170, -80, 95, 1.5, 0,  0};
  return m;
}

TEST(WritesAndReadsBackAGmrMotion, GmrToAcclaim) {
  const Motion m = two_joint_motion(Convention::kPreRotation);
  const auto dir = std::filesystem::temp_directory_path() / ("gmr_asf_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  ASSERT_TRUE(write_asf_amc(m, dir / "x.asf", dir / "x.amc").ok());
  auto g = read_asf_amc(dir / "x.asf", dir / "x.amc");
  ASSERT_TRUE(g.ok()) << g.error().to_string();
  // Names kept (the root is `root` in the ASF, its name on a documentation
  // line that gmr reads back), positions kept.
  EXPECT_EQ(g->skeleton.joint(0).name, "Hips");
  const std::string asf = read_file(dir / "x.asf").value();
  EXPECT_NE(asf.find("\n   gmr root name: Hips\n"), std::string::npos) << asf;
  EXPECT_NE(asf.find("\n:root\n"), std::string::npos);
  EXPECT_EQ(g->skeleton.joint(1).name, "Spine");
  EXPECT_EQ(g->skeleton.joint(2).name, "Spine_End");
  const auto a = compute_positions(m);
  const auto b = compute_positions(*g);
  EXPECT_POSITIONS_NEAR(m.skeleton, a, b, 1e-12);
  std::filesystem::remove_all(dir);
}

TEST(RejectsWhatAcclaimCannotHold, GmrToAcclaim) {
  EXPECT_FALSE(gmr_to_acclaim(two_joint_motion(Convention::kPostRotation)).ok());
  Motion m = two_joint_motion(Convention::kPreRotation);
  auto joints = m.skeleton.joints();
  auto with = [&](auto edit) {
    auto j = joints;
    edit(j);
    Motion x = m;
    x.skeleton = *Skeleton::create(j);
    x.values.resize(x.frame_count * x.stride(), 0.0);
    return gmr_to_acclaim(x);
  };
  EXPECT_FALSE(with([](std::vector<Joint>& j) { j[1].name = "ROOT"; }).ok());
  EXPECT_FALSE(with([](std::vector<Joint>& j) { j[1].name = "End"; }).ok());
  EXPECT_FALSE(with([](std::vector<Joint>& j) { j[1].name = ":x"; }).ok());
  EXPECT_FALSE(with([](std::vector<Joint>& j) { j[1].name = "a b"; }).ok());
  EXPECT_FALSE(with([](std::vector<Joint>& j) { j[1].name = "a(b)"; }).ok());
  EXPECT_FALSE(with([](std::vector<Joint>& j) { j[2].name = "SPINE"; }).ok());
  auto two_roots = with([](std::vector<Joint>& j) { j[2].parent = kNoParent; });
  ASSERT_FALSE(two_roots.ok());
  EXPECT_NE(two_roots.error().message.find("2 roots"), std::string::npos);
  EXPECT_TRUE(with([](std::vector<Joint>&) {}).ok());
}

// Every BVH of the corpus, as GMR, exports to ASF/AMC with the same positions,
// or is refused with a reason (a joint name the ASF syntax cannot hold).
TEST(EveryCorpusBvhExports, GmrToAcclaim) {
  GMR_REQUIRE_DATA();
  const auto files = data_files("bvh", ".bvh");
  ASSERT_GE(files.size(), 40u);
  std::size_t exported = 0;
  for (const auto& path : files) {
    SCOPED_TRACE(path.string());
    // Under the sanitizers, skip the big files: their parsing is the BVH tests' job.
    if (kSanitized && std::filesystem::file_size(path) > 400000) {
      ++exported;
      continue;
    }
    auto bvh = read_bvh(path);
    ASSERT_TRUE(bvh.ok()) << bvh.error().to_string();
    bvh->frame_count = frames_to_check(bvh->frame_count);
    bvh->values.resize(bvh->frame_count * bvh->stride());
    auto pre = to_pre_rotation(*bvh);
    ASSERT_TRUE(pre.ok()) << pre.error().to_string();
    auto model = gmr_to_acclaim(*pre);
    if (!model.ok()) {
      EXPECT_NE(model.error().message.find("cannot be written to ASF"), std::string::npos) << model.error().message;
      continue;
    }
    ++exported;
    const Skeleton& sk = pre->skeleton;
    const auto& bones = model->skeleton.bones;
    ASSERT_EQ(bones.size(), sk.size());
    const auto a = compute_positions(*bvh);
    const auto b = acclaim_positions(model->skeleton, model->motion);
    // The root's own name survives in the documentation, read back by acclaim_to_gmr.
    const Motion back = acclaim_to_gmr(model->skeleton, model->motion).value();
    EXPECT_EQ(back.skeleton.joint(back.skeleton.roots()[0]).name, sk.joint(sk.roots()[0]).name);
    // Bone i <-> GMR joint of the same name (the root is `root` in the ASF).
    std::vector<Eigen::Vector3d> reordered(b.size());
    for (std::size_t i = 0; i < bones.size(); ++i) {
      const int j = i == 0 ? sk.roots()[0] : sk.find(bones[i].name);
      ASSERT_GE(j, 0) << bones[i].name;
      for (std::size_t f = 0; f < bvh->frame_count; ++f)
        reordered[f * sk.size() + static_cast<std::size_t>(j)] = b[f * sk.size() + i];
    }
    EXPECT_POSITIONS_NEAR(sk, a, reordered, 1e-9 * skeleton_size(*bvh));
  }
  EXPECT_GE(exported, 40u);
}

// The file layer: load_motion reads .amc through read_asf_amc (the skeleton named
// in LoadOptions, else the single .asf beside it); save_motion writes .amc plus
// the .asf beside it.
TEST(LoadAndSaveByExtension, AsfAmcFiles) {
  GMR_REQUIRE_DATA();
  const auto asf = data_file("asfamc/09/09-run.asf");
  const auto amc = data_file("asfamc/09/09_06-run.amc");
  auto direct = read_asf_amc(asf, amc);
  ASSERT_TRUE(direct.ok());
  auto named = load_motion(amc, LoadOptions{asf});
  ASSERT_TRUE(named.ok()) << named.error().to_string();
  auto found = load_motion(amc);
  ASSERT_TRUE(found.ok()) << found.error().to_string();
  EXPECT_TRUE(named->values == direct->values);
  EXPECT_TRUE(found->values == direct->values);

  const auto dir = std::filesystem::temp_directory_path() / ("gmr_asf_files_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  ASSERT_TRUE(save_motion(*direct, dir / "out.amc").ok());
  ASSERT_TRUE(std::filesystem::exists(dir / "out.asf"));
  auto back = load_motion(dir / "out.amc");
  ASSERT_TRUE(back.ok()) << back.error().to_string();
  EXPECT_POSITIONS_NEAR(direct->skeleton, compute_positions(*direct), compute_positions(*back),
                        1e-9 * skeleton_size(*direct));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace gmr::test
