// The `gmr` server commands against an in-process server: `gmr query` prints
// byte for byte what `gmr positions` prints for the same file and options,
// `gmr stream` prints the same rows, `gmr record` writes a file whose
// positions and orientations are the view's, errors are one line with exit
// status 1.
#include <gtest/gtest.h>

#include <algorithm>

#include <array>
#include <chrono>
#include <cstdio>
#include <sys/wait.h>

#include <map>
#include <mutex>
#include <sstream>
#include <thread>

#include "gmr/core/file_util.h"
#include "gmr/io/gmr_file.h"
#include "gmr/io/motion_file.h"
#include "gmr/io/positions_csv.h"
#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/ops/convert.h"
#include "gmr/view/view.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

// Runs the gmr command with `args` (shell-quoted by the caller), stdout
// captured, stderr merged. Without `prefix_binary`, `args` is the whole
// command line.
CommandRun gmr(const std::string& args, bool prefix_binary = true) {
  return run_command((prefix_binary ? std::string(GMR_CLI_PATH) + " " : std::string()) + args);
}

// Every command that talks to a server waits --timeout-ms for each reply
// (default 5 s), then says so: here a listener that never answers.
TEST(CliNet, ACommandWaitsItsTimeoutForAReplyThenSaysSo) {
  const SilentListener silent;
  ASSERT_NE(silent.port(), 0);
  const std::string port = " --port " + std::to_string(silent.port());
  for (const char* command : {"ls", "query walk --frames 0:1", "stream walk --count 1"}) {
    const auto started = std::chrono::steady_clock::now();
    const CommandRun r = gmr(std::string(command) + port + " --timeout-ms 300");
    const auto took = std::chrono::steady_clock::now() - started;
    EXPECT_EQ(r.status, 1) << command << ": " << r.out;
    EXPECT_NE(r.out.find("within 300 ms"), std::string::npos) << command << ": " << r.out;
    EXPECT_LT(took, std::chrono::seconds(4)) << command << " waited past its 300 ms (the default is 5 s)";
  }
  const CommandRun too_short = gmr("ls" + port + " --timeout-ms 5");
  EXPECT_NE(too_short.status, 0);
  EXPECT_NE(too_short.out.find("--timeout-ms"), std::string::npos) << too_short.out;
}

TEST(CliNet, QueryPrintsExactlyWhatPositionsPrints) {
  GMR_REQUIRE_DATA();
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const std::string file = cmu_file().string();
  for (const std::string opts :
       {"", " --roots LeftHand", " --roots Hips,LeftForeArm --relative-to Head",
        " --strip-dummies --relative-to LeftFoot", " --conventions unreal --metres-per-unit 0.0254",
        " --relative-to Head --conventions unity"}) {
    SCOPED_TRACE(opts);
    const CommandRun q = gmr("query cmu/02_01 --frames 10:60" + opts + port);
    const CommandRun p = gmr("positions '" + file + "' --frames 10:60" + opts);
    ASSERT_EQ(q.status, 0) << q.out;
    ASSERT_EQ(p.status, 0) << p.out;
    EXPECT_EQ(q.out, p.out);
    EXPECT_GT(q.out.size(), 1000u);
  }
}

// CSV rows as (frame,joint) and their numbers.
std::vector<std::pair<std::string, std::vector<double>>> csv_rows(const std::string& text) {
  std::vector<std::pair<std::string, std::vector<double>>> rows;
  std::istringstream in(text);
  std::string line;
  std::getline(in, line);  // the header
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    std::string frame, joint, v;
    std::getline(fields, frame, ',');
    std::getline(fields, joint, ',');
    std::vector<double> numbers;
    while (std::getline(fields, v, ',')) numbers.push_back(std::stod(v));
    rows.emplace_back(frame + "," + joint, std::move(numbers));
  }
  return rows;
}

// Before: `gmr positions --orientations` refused --roots, --strip-dummies and
// --relative-to, and `gmr query` and `gmr stream` had no --orientations.
// Now all three print them, for every view, and agree.
TEST(CliNet, OrientationsPrintWithEveryViewAndFromTheServer) {
  GMR_REQUIRE_DATA();
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const std::string file = cmu_file().string();
  for (const std::string opts :
       {" --orientations quat", " --orientations quat --roots LeftHand",
        " --orientations matrix --roots Hips,LeftForeArm --relative-to Head",
        " --orientations quat --strip-dummies --relative-to LeftFoot",
        " --orientations quat --relative-to Head --conventions unity --metres-per-unit 0.0254"}) {
    SCOPED_TRACE(opts);
    const CommandRun q = gmr("query cmu/02_01 --frames 10:40" + opts + port);
    const CommandRun p = gmr("positions '" + file + "' --frames 10:40" + opts);
    ASSERT_EQ(q.status, 0) << q.out;
    ASSERT_EQ(p.status, 0) << p.out;
    ASSERT_EQ(q.out.substr(0, q.out.find('\n')), p.out.substr(0, p.out.find('\n')));  // the same columns
    const auto qr = csv_rows(q.out), pr = csv_rows(p.out);
    ASSERT_EQ(qr.size(), pr.size());
    ASSERT_GE(qr.size(), 30u * 20u);
    double worst = 0;
    for (std::size_t i = 0; i < qr.size(); ++i) {
      ASSERT_EQ(qr[i].first, pr[i].first);
      ASSERT_EQ(qr[i].second.size(), pr[i].second.size());
      ASSERT_GT(qr[i].second.size(), 3u);
      for (std::size_t k = 3; k < qr[i].second.size(); ++k) {
        worst = std::max(worst, std::abs(qr[i].second[k] - pr[i].second[k]));
      }
    }
    EXPECT_LT(worst, 1e-9) << "orientation entries differ by " << worst;
  }
  // gmr stream prints the same rows as gmr query.
  const CommandRun st = gmr("stream cmu/02_01 --frames 0:5 --speed 10 --orientations quat --roots LeftHand" + port);
  const CommandRun q = gmr("query cmu/02_01 --frames 0:5 --orientations quat --roots LeftHand" + port);
  ASSERT_EQ(st.status, 0) << st.out;
  ASSERT_EQ(q.status, 0) << q.out;
  EXPECT_EQ(st.out, q.out);
}

// `--local-transforms` prints each joint's engine-bone local transform:
// positions, query and stream agree, and for every frame the locals compose
// (O_j = O_p Q_j, P_j = P_p + O_p T_j, in the view's hierarchy) to the
// printed positions.
TEST(CliNet, LocalTransformsPrintAndComposeToThePositions) {
  GMR_REQUIRE_DATA();
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const std::string file = cmu_file().string();
  const auto motion = load_motion(cmu_file());
  ASSERT_TRUE(motion.ok()) << motion.error().to_string();
  for (const auto& [opts, spec] : std::vector<std::pair<std::string, ViewSpec>>{
           {" --roots LeftHand --conventions unity --metres-per-unit 0.0254", ViewSpec{.roots = {"LeftHand"}}},
           {" --roots Hips,LeftForeArm --relative-to Head --orientations quat",
            ViewSpec{.roots = {"Hips", "LeftForeArm"}, .relative_to = "Head"}},
           {" --strip-dummies --conventions godot --metres-per-unit 0.0254", ViewSpec{.strip_dummies = true}}}) {
    SCOPED_TRACE(opts);
    const CommandRun p = gmr("positions '" + file + "' --frames 10:40 --local-transforms" + opts);
    const CommandRun q = gmr("query cmu/02_01 --frames 10:40 --local-transforms" + opts + port);
    ASSERT_EQ(p.status, 0) << p.out;
    ASSERT_EQ(q.status, 0) << q.out;
    const std::string header = p.out.substr(0, p.out.find('\n'));
    EXPECT_EQ(header, q.out.substr(0, q.out.find('\n')));
    EXPECT_NE(header.find(",lqw,lqx,lqy,lqz,ltx,lty,ltz"), std::string::npos) << header;
    const auto pr = csv_rows(p.out), qr = csv_rows(q.out);
    ASSERT_EQ(pr.size(), qr.size());
    const auto view = apply_view(*motion, spec);
    ASSERT_TRUE(view.ok()) << view.error().to_string();
    const Skeleton names = view_names(*view);
    const std::size_t n = names.size();
    ASSERT_EQ(pr.size(), 30 * n);
    double worst_query = 0, worst_compose = 0;
    for (std::size_t f = 0; f < 30; ++f) {
      std::map<std::string, std::pair<Eigen::Matrix3d, Eigen::Vector3d>> frame;  // by name: O_j, P_j
      for (std::size_t i = 0; i < n; ++i) {
        const auto& row = pr[f * n + i].second;
        ASSERT_EQ(row.size(), qr[f * n + i].second.size());
        for (std::size_t k = 0; k < row.size(); ++k) {
          worst_query = std::max(worst_query, std::abs(row[k] - qr[f * n + i].second[k]));
        }
        const std::size_t l = row.size() - 7;  // the local columns come last
        const Eigen::Quaterniond local(row[l], row[l + 1], row[l + 2], row[l + 3]);
        const Eigen::Vector3d t(row[l + 4], row[l + 5], row[l + 6]);
        const std::string name = pr[f * n + i].first.substr(pr[f * n + i].first.find(',') + 1);
        ASSERT_GE(names.find(name), 0) << name;
        frame[name] = {local.toRotationMatrix(), t};
      }
      // Rows come in the source's joint order; compose in the view's
      // hierarchy, whose joints come parents first.
      const Skeleton& tree = view->motion.skeleton;
      ASSERT_EQ(tree.size(), n);
      std::map<std::string, Eigen::Vector3d> composed;
      std::vector<Eigen::Matrix3d> o(n);
      std::vector<Eigen::Vector3d> at(n);
      for (int j = 0; j < static_cast<int>(n); ++j) {
        const auto k = static_cast<std::size_t>(j);
        const auto& [r, t] = frame.at(tree.joint(j).name);
        const int parent = tree.joint(j).parent;
        ASSERT_LT(parent, j);
        const auto pk = static_cast<std::size_t>(parent);
        o[k] = parent < 0 ? r : Eigen::Matrix3d(o[pk] * r);
        at[k] = parent < 0 ? t : Eigen::Vector3d(at[pk] + o[pk] * t);
        composed[tree.joint(j).name] = at[k];
      }
      for (std::size_t i = 0; i < n; ++i) {
        const auto& row = pr[f * n + i].second;
        const Eigen::Vector3d printed(row[0], row[1], row[2]);
        const std::string name = pr[f * n + i].first.substr(pr[f * n + i].first.find(',') + 1);
        worst_compose = std::max(worst_compose, (composed.at(name) - printed).norm());
      }
    }
    EXPECT_LT(worst_query, 1e-9) << "gmr query and gmr positions differ by " << worst_query;
    EXPECT_LT(worst_compose, 1e-9) << "the locals compose to positions " << worst_compose << " off";
  }
  const CommandRun st = gmr("stream cmu/02_01 --frames 0:5 --speed 10 --local-transforms --roots LeftHand" + port);
  const CommandRun q = gmr("query cmu/02_01 --frames 0:5 --local-transforms --roots LeftHand" + port);
  ASSERT_EQ(st.status, 0) << st.out;
  EXPECT_EQ(st.out, q.out);
}

// Before: --conventions unity on a BVH kept the file's units silently (a
// CMU file arrived in units of about 5.6 cm, not metres). Now the command
// says so whenever nobody gave the unit.
TEST(CliNet, ConventionsOnAMotionOfUnknownUnitSayTheNumbersKeepItsUnits) {
  GMR_REQUIRE_DATA();
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const std::string file = cmu_file().string();
  const std::string warning = "warning: the motion's unit is unknown";
  for (const std::string& cmd : {"positions '" + file + "' --frames 0:1 --conventions unity",
                                 "query cmu/02_01 --frames 0:1 --conventions unity" + port,
                                 "stream cmu/02_01 --frames 0:1 --conventions godot" + port}) {
    SCOPED_TRACE(cmd);
    const CommandRun r = gmr(cmd);
    ASSERT_EQ(r.status, 0) << r.out;
    EXPECT_NE(r.out.find(warning), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("--metres-per-unit"), std::string::npos) << r.out;
  }
  for (const std::string& cmd :
       {"positions '" + file + "' --frames 0:1 --conventions unity --metres-per-unit 0.056",
        "positions '" + file + "' --frames 0:1", "query walk --frames 0:1 --conventions unity" + port,
        "query cmu/02_01 --frames 0:1 --conventions unity --metres-per-unit 0.056" + port}) {
    SCOPED_TRACE(cmd);
    const CommandRun r = gmr(cmd);
    ASSERT_EQ(r.status, 0) << r.out;
    EXPECT_EQ(r.out.find(warning), std::string::npos) << r.out;
  }
}

// A units sidecar beside a BVH gives it the unit --metres-per-unit would:
// the same rows, no warning; a broken one is an error naming it and the line.
TEST(CliNet, AUnitsSidecarGivesABvhItsUnit) {
  GMR_REQUIRE_DATA();
  TempDir dir;
  std::filesystem::create_symlink(cmu_file(), dir.path / "02_01.bvh");
  const std::string file = (dir.path / "02_01.bvh").string();
  const std::string view = " --frames 0:3 --conventions unity --roots LeftFoot";
  const CommandRun given = gmr("positions '" + file + "'" + view + " --metres-per-unit 0.0254");
  ASSERT_EQ(given.status, 0) << given.out;
  ASSERT_TRUE(write_file_atomic(dir.path / "folder.units", "# CMU's BVH conversions\ninches\n").ok());
  const CommandRun declared = gmr("positions '" + file + "'" + view);
  ASSERT_EQ(declared.status, 0) << declared.out;
  EXPECT_EQ(declared.out, given.out);
  EXPECT_EQ(declared.out.find("warning"), std::string::npos) << declared.out;
  ASSERT_TRUE(write_file_atomic(dir.path / "02_01.units", "\n0.0254 0.0254\n").ok());
  const CommandRun broken = gmr("positions '" + file + "'" + view);
  EXPECT_NE(broken.status, 0);
  EXPECT_NE(broken.out.find("02_01.units:2: 0.0254 0.0254 is not a unit"), std::string::npos) << broken.out;
}

TEST(CliNet, StreamPrintsTheSameRowsAsPositions) {
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const CommandRun st = gmr("stream walk --frames 0:5 --speed 10" + port);
  const CommandRun q = gmr("query walk --frames 0:5" + port);
  ASSERT_EQ(st.status, 0) << st.out;
  ASSERT_EQ(q.status, 0) << q.out;
  EXPECT_EQ(st.out, q.out);
  const CommandRun udp = gmr("stream walk --udp --count 3 --joints head" + port);
  ASSERT_EQ(udp.status, 0) << udp.out;
  EXPECT_EQ(udp.out.rfind("frame,joint,x,y,z\n", 0), 0u) << udp.out;
}

TEST(CliNet, ListAndSkeletonAndOneLineErrors) {
  TestServer s;
  const std::string port = " --port " + std::to_string(s.port());
  const CommandRun ls = gmr("ls" + port);
  ASSERT_EQ(ls.status, 0) << ls.out;
  EXPECT_NE(ls.out.find("walk"), std::string::npos);
  const CommandRun sk = gmr("skeleton walk" + port);
  ASSERT_EQ(sk.status, 0) << sk.out;
  EXPECT_NE(sk.out.find("l_hand"), std::string::npos);
  const CommandRun missing = gmr("query nope" + port);
  EXPECT_EQ(missing.status, 1);
  EXPECT_EQ(missing.out, "gmr: NOT_FOUND: unknown motion 'nope'\n");
  const CommandRun joint = gmr("query walk --relative-to tail" + port);
  EXPECT_EQ(joint.status, 1);
  EXPECT_NE(joint.out.find("'tail'"), std::string::npos) << joint.out;
  // Nothing listens on port 1.
  const CommandRun refused = gmr("ls --port 1");
  EXPECT_EQ(refused.status, 1);
  EXPECT_EQ(refused.out.rfind("gmr: cannot connect to 127.0.0.1:1", 0), 0u) << refused.out;
}

// Over TLS, with a token: the same rows as a plain server's; without the
// token a structural edit is one line naming the role, and a wrong token
// one line naming the refusal.
// Sorted lines: `gmr positions` of a recording lists its joints in the
// view's order, `gmr query` in the motion's.
std::vector<std::string> sorted_lines(const std::string& s) {
  std::vector<std::string> lines;
  std::size_t b = 0;
  for (std::size_t e; (e = s.find('\n', b)) != std::string::npos; b = e + 1) lines.push_back(s.substr(b, e - b));
  std::sort(lines.begin(), lines.end());
  return lines;
}

TEST(CliNet, RecordWritesTheViewsPositionsAndOrientations) {
  GMR_REQUIRE_DATA();
  TestServer s;
  TempDir dir;
  const std::string port = " --port " + std::to_string(s.port());
  // A re-rooted view seen from a joint, in an engine's conventions, over TCP:
  // the recording's positions print exactly what the server's query prints.
  const std::string view = " --roots LeftHand --relative-to Head --conventions unity --metres-per-unit 0.0254";
  const std::string rec = (dir.path / "view.gmr").string();
  const CommandRun r = gmr("record cmu/02_01 -o '" + rec + "' --frames 10:90 --speed 20" + view + port);
  ASSERT_EQ(r.status, 0) << r.out;
  EXPECT_NE(r.out.find("recorded 80 frames of cmu/02_01"), std::string::npos) << r.out;
  const CommandRun p = gmr("positions '" + rec + "'");
  const CommandRun q = gmr("query cmu/02_01 --frames 10:90" + view + port);
  ASSERT_EQ(q.status, 0) << q.out;
  ASSERT_EQ(p.status, 0) << p.out;
  // Frame numbers restart at 0 in the recording: compare rows without them.
  auto strip_frame = [](const std::string& text, std::size_t first) {
    std::string out;
    std::size_t b = 0;
    for (std::size_t e; (e = text.find('\n', b)) != std::string::npos; b = e + 1) {
      const std::string line = text.substr(b, e - b);
      const std::size_t comma = line.find(',');
      if (line.rfind("frame,", 0) == 0) continue;
      out += std::to_string(std::stoul(line.substr(0, comma)) - first) + line.substr(comma) + "\n";
    }
    return out;
  };
  EXPECT_EQ(sorted_lines(strip_frame(p.out, 0)), sorted_lines(strip_frame(q.out, 10)));
  EXPECT_GT(p.out.size(), 10000u);

  // World view: orientations too, against the file's own (GMR bone frames).
  const std::string world = (dir.path / "world.gmrb").string();
  const CommandRun w = gmr("record cmu/02_01 -o '" + world + "' --count 30 --speed 20" + port);
  ASSERT_EQ(w.status, 0) << w.out;
  auto recorded = load_motion(world);
  ASSERT_TRUE(recorded.ok()) << recorded.error().to_string();
  auto source = load_motion(cmu_file());
  ASSERT_TRUE(source.ok());
  auto pre = to_pre_rotation(*source);
  ASSERT_TRUE(pre.ok());
  ASSERT_EQ(recorded->frame_count, 30u);
  EXPECT_EQ(recorded->skeleton.roots().size(), recorded->skeleton.size());  // every joint a root, soft-linked
  const std::size_t rn = recorded->skeleton.size(), sn = pre->skeleton.size();
  std::vector<Eigen::Vector3d> rp(rn), sp(sn);
  std::vector<Eigen::Matrix3d> ro(rn), so(sn);
  double worst_p = 0, worst_o = 0;
  std::size_t compared = 0;
  for (std::size_t f = 0; f < 30; ++f) {
    compute_frame(*recorded, f, rp, ro);
    compute_frame(*pre, f, sp, so);
    for (std::size_t j = 0; j < rn; ++j) {
      const int k = pre->skeleton.find(recorded->skeleton.joint(static_cast<int>(j)).name);
      ASSERT_GE(k, 0);
      worst_p = std::max(worst_p, (rp[j] - sp[static_cast<std::size_t>(k)]).norm());
      worst_o = std::max(worst_o, (ro[j] - so[static_cast<std::size_t>(k)]).norm());
      ++compared;
    }
  }
  EXPECT_EQ(compared, 30 * sn);
  EXPECT_LT(worst_p, 1e-9 * skeleton_size(*pre));
  EXPECT_LT(worst_o, 1e-9);
  // Soft links follow the view's tree: a join puts the hierarchy back.
  const Skeleton& rs = recorded->skeleton;
  const int knee = rs.find("LeftLeg");
  ASSERT_GE(knee, 0);
  EXPECT_EQ(rs.joint(rs.joint(knee).soft_parent).name, "LeftUpLeg");

  // UDP with a time limit, a joint subset to BVH.
  const std::string udp = (dir.path / "udp.bvh").string();
  const CommandRun u = gmr("record walk -o '" + udp + "' --udp --loop --seconds 0.3 --joints head,l_hand" + port);
  ASSERT_EQ(u.status, 0) << u.out;
  auto bvh = load_motion(udp);
  ASSERT_TRUE(bvh.ok()) << bvh.error().to_string();
  EXPECT_EQ(bvh->skeleton.size(), 2u);
  EXPECT_GT(bvh->frame_count, 5u);

  const CommandRun bad = gmr("record walk -o '" + (dir.path / "x.csv").string() + "'" + port);
  EXPECT_EQ(bad.status, 1);
  EXPECT_NE(bad.out.find("a recording is written as .gmr, .gmrb or .bvh"), std::string::npos) << bad.out;
  const CommandRun none = gmr("record nope -o '" + (dir.path / "x.gmr").string() + "'" + port);
  EXPECT_EQ(none.status, 1);
  EXPECT_EQ(none.out, "gmr: NOT_FOUND: unknown motion 'nope'\n");
  EXPECT_FALSE(std::filesystem::exists(dir.path / "x.gmr"));
}

const std::string kPublishToken = "publish-token-0123456789abcdef";

// A server on which kPublishToken may publish; anonymous clients control.
server::ServerConfig publish_config() {
  server::ServerConfig cfg;
  auto auth = server::Credentials::parse("publish " + kPublishToken + "\n", "auth");
  EXPECT_TRUE(auth.ok());
  cfg.credentials = std::make_shared<const server::Credentials>(std::move(auth).value());
  cfg.anonymous = server::Role::kControl;
  return cfg;
}

// Waits until `motion` is listed with a frame published: 10 s at most, or
// as long as a slow build's reply (under a sanitizer, with other tests on
// both cores, a marker calibration outlasted 500 polls of 10 ms in CI).
bool wait_for_frames(client::Client& c, const std::string& motion) {
  const auto deadline =
      std::chrono::steady_clock::now() + (kSlowBuild ? kSlowBuildReplyTimeout : std::chrono::milliseconds(10000));
  while (std::chrono::steady_clock::now() < deadline) {
    const auto motions = c.list_motions();
    if (!motions.ok()) return false;
    for (const auto& m : *motions) {
      if (m.name == motion && m.frame_count > 0) return true;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

TEST(CliNet, PublishPlaysAFileLiveAndRecordCapturesItsPositions) {
  GMR_REQUIRE_DATA();
  const std::string token = kPublishToken;
  TestServer s(publish_config());
  TempDir dir;
  const std::string port = " --port " + std::to_string(s.port());
  const std::string file = cmu_file().string();

  // Without a publish token: refused, one line.
  const CommandRun refused = gmr("publish '" + file + "' --count 1" + port);
  EXPECT_EQ(refused.status, 1);
  EXPECT_NE(refused.out.find("PERMISSION_DENIED"), std::string::npos) << refused.out;

  CommandRun published;
  std::thread publisher([&] {
    published = gmr("publish '" + file + "' --name take/live --rate 60 --count 240 --token " + token + port);
  });
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  ASSERT_TRUE(wait_for_frames(*c, "take/live")) << "the live source never appeared";
  const CommandRun ls = gmr("ls" + port);
  EXPECT_NE(ls.out.find("take/live"), std::string::npos);
  EXPECT_NE(ls.out.find("live\n"), std::string::npos) << ls.out;

  const std::string rec = (dir.path / "live.gmr").string();
  const CommandRun r = gmr("record take/live -o '" + rec + "' --count 60" + port);
  publisher.join();
  ASSERT_EQ(r.status, 0) << r.out;
  ASSERT_EQ(published.status, 0) << published.out;
  EXPECT_NE(published.out.find("published 240 frames of 'take/live'"), std::string::npos) << published.out;

  // The recording is 60 of the published frames, in order, from the newest
  // when it joined (a live frame a busy server could not send in time is
  // skipped and counted, so they need not be consecutive): each recorded
  // joint where the file has it.
  auto recorded = load_motion(rec);
  ASSERT_TRUE(recorded.ok()) << recorded.error().to_string();
  ASSERT_EQ(recorded->frame_count, 60u);
  auto pre = to_pre_rotation(load_motion(cmu_file()).value());
  ASSERT_TRUE(pre.ok());
  const std::size_t rn = recorded->skeleton.size(), sn = pre->skeleton.size();
  ASSERT_EQ(rn, sn);
  std::vector<int> map(rn);
  for (std::size_t j = 0; j < rn; ++j) map[j] = pre->skeleton.find(recorded->skeleton.joint(static_cast<int>(j)).name);
  std::vector<Eigen::Vector3d> rp(rn), sp(sn);
  std::vector<Eigen::Matrix3d> ro(rn), so(sn);
  auto error_at = [&](std::size_t rf, std::size_t sf) {
    compute_frame(*recorded, rf, rp, ro);
    compute_frame(*pre, sf, sp, so);
    double worst = 0;
    for (std::size_t j = 0; j < rn; ++j) worst = std::max(worst, (rp[j] - sp[static_cast<std::size_t>(map[j])]).norm());
    return worst;
  };
  const double tolerance = 1e-9 * skeleton_size(*pre);
  // Each recorded frame is the next published one that matches it exactly.
  std::size_t sf = 0, matched = 0, skipped = 0;
  for (std::size_t f = 0; f < 60; ++f) {
    const std::size_t from = sf;
    while (sf < 240 && error_at(f, sf) > tolerance) ++sf;
    if (sf == 240) break;
    if (f > 0) skipped += sf - from;
    ++matched;
    ++sf;
  }
  EXPECT_EQ(matched, 60u) << "recorded frame " << matched << " is none of the published frames after the one before";
  EXPECT_LE(skipped, 6u) << "published frames the recording skipped";
}

// Before: `gmr publish FILE --count N` looped past the end of the file
// without --loop. Now a file is published once unless --loop says otherwise,
// and the help says so.
TEST(CliNet, PublishCountNeverLoopsWithoutLoop) {
  TestServer s(publish_config());
  TempDir dir;
  const std::string file = (dir.path / "short.gmr").string();
  const Motion m = *test_library().front().motion;
  ASSERT_GT(m.frame_count, 10u);
  ASSERT_TRUE(write_gmr(m, file).ok());
  const std::string common =
      " --rate 2000 --token " + std::string(kPublishToken) + " --port " + std::to_string(s.port());
  const CommandRun once =
      gmr("publish '" + file + "' --name once --count " + std::to_string(m.frame_count + 50) + common);
  ASSERT_EQ(once.status, 0) << once.out;
  EXPECT_NE(once.out.find("published " + std::to_string(m.frame_count) + " frames of 'once'"), std::string::npos)
      << once.out;
  const CommandRun looped =
      gmr("publish '" + file + "' --name looped --loop --count " + std::to_string(m.frame_count + 50) + common);
  ASSERT_EQ(looped.status, 0) << looped.out;
  EXPECT_NE(looped.out.find("published " + std::to_string(m.frame_count + 50) + " frames of 'looped'"),
            std::string::npos)
      << looped.out;
  const CommandRun help = gmr("publish --help");
  EXPECT_NE(help.out.find("without --loop, at most the file's frames"), std::string::npos) << help.out;
}

// `gmr publish TAKE.c3d --markers --model cmu41`: the server calibrates on
// the first seconds, then serves the solved skeleton: gmr query of the live
// source gives the model's 21 joints. A marker file without --markers is
// refused with the way to publish it.
TEST(CliNet, PublishMarkersServesTheSolvedSkeleton) {
  GMR_REQUIRE_DATA();
  TestServer s(publish_config());
  // The publisher's frames wait unread while the server calibrates: seconds
  // under a sanitizer.
  const std::string common = " --token " + std::string(kPublishToken) + " --port " + std::to_string(s.port()) +
                             (kSlowBuild ? " --timeout-ms " + std::to_string(kSlowBuildReplyTimeout.count()) : "");
  const std::string c3d = test::data_file("c3d/cmu_01_01.c3d").string();
  const CommandRun plain = gmr("publish '" + c3d + "' --count 1" + common);
  EXPECT_EQ(plain.status, 1);
  EXPECT_NE(plain.out.find("add --markers"), std::string::npos) << plain.out;
  CommandRun published;
  std::thread publisher([&] {
    published = gmr("publish '" + c3d +
                    "' --markers --model cmu41 --calibration-seconds 0.5 --name lab --rate 240 "
                    "--count 600" +
                    common);
  });
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  const bool appeared = wait_for_frames(*c, "lab");
  publisher.join();
  ASSERT_TRUE(appeared) << "the live marker source never appeared: " << published.out;
  ASSERT_EQ(published.status, 0) << published.out;
  EXPECT_NE(published.out.find("published 600 marker frames of 'lab'"), std::string::npos) << published.out;
}

// The help texts a newcomer reads say what the commands do today.
TEST(CliNet, HelpTextsNameWhatTheCommandsDo) {
  const CommandRun convert = gmr("convert --help");
  for (const char* said : {".gmrb", ".amc", ".c3d", "--model"}) {
    EXPECT_NE(convert.out.find(said), std::string::npos) << said << " not in:\n" << convert.out;
  }
  EXPECT_EQ(convert.out.find(".bvh <-> .gmr)"), std::string::npos) << convert.out;
#ifdef GMR_SERVER_PATH
  const CommandRun server = run_command(std::string(GMR_SERVER_PATH) + " --help");
  ASSERT_EQ(server.status, 0) << server.out;
  EXPECT_EQ(server.out.find("operations.md"), std::string::npos) << "a pointer to the wrong page:\n" << server.out;
  const auto nats = server.out.find("--nats TEXT");
  ASSERT_NE(nats, std::string::npos);
  EXPECT_NE(server.out.find("docs/deployment.md", nats), std::string::npos);
  EXPECT_NE(server.out.find("SIGHUP reads it again"), std::string::npos) << server.out;
#endif
}

TEST(CliNet, PublishPlaysThePositionsCsvAsAnAllRootsSource) {
  GMR_REQUIRE_DATA();
  const std::string token = kPublishToken;
  TestServer s(publish_config());
  TempDir dir;
  const std::string port = " --port " + std::to_string(s.port());
  const std::string csv = (dir.path / "p.csv").string();
  const CommandRun p = gmr("positions '" + cmu_file().string() + "' --frames 0:40 > '" + csv + "'");
  ASSERT_EQ(p.status, 0) << p.out;
  const auto table = read_positions_csv(csv);
  ASSERT_TRUE(table.ok()) << table.error().to_string();
  ASSERT_EQ(table->frames, 40u);

  CommandRun published;
  std::thread publisher([&] {
    published = gmr("publish '" + csv + "' --name csv/live --rate 100 --loop --count 300 --token " + token + port);
  });
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  ASSERT_TRUE(wait_for_frames(*c, "csv/live")) << "the live source never appeared";
  auto v = c->create_view("csv/live");
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->skeleton.roots().size(), table->joints.size());  // every joint a root
  struct Got {
    std::mutex mutex;
    std::size_t frames = 0, compared = 0;
    double worst = 0;
  } got;
  Latch<bool> ended;
  client::SubscribeOptions so;
  so.float64 = true;
  so.max_frames = 30;
  const Skeleton sk = v->skeleton;
  auto sub = c->subscribe(
      v->id, so,
      [&](const client::ReceivedFrame& f) {
        std::lock_guard lock(got.mutex);
        ++got.frames;
        const std::size_t row = (f.frame_index % 40) * table->joints.size();
        for (std::size_t j = 0; j < f.positions.size(); ++j) {
          const auto k = std::find(table->joints.begin(), table->joints.end(), sk.joint(static_cast<int>(j)).name);
          if (k == table->joints.end()) continue;
          const auto& want = table->positions[row + static_cast<std::size_t>(k - table->joints.begin())];
          got.worst = std::max(got.worst, (f.positions[j] - want).norm());
          ++got.compared;
        }
      },
      [&](const client::SubscriptionEnd&) { ended.set(true); });
  ASSERT_TRUE(sub.ok()) << sub.error().to_string();
  EXPECT_TRUE(ended.wait().has_value());
  publisher.join();
  ASSERT_EQ(published.status, 0) << published.out;
  EXPECT_NE(published.out.find("38 joints, 114 channels, 100.00 Hz"), std::string::npos) << published.out;
  std::lock_guard lock(got.mutex);
  EXPECT_GE(got.frames, 25u);
  EXPECT_EQ(got.compared, got.frames * table->joints.size());
  EXPECT_LT(got.worst, 1e-9 * 100);  // the CSV's positions, to round-off of a few metres
}

TEST(CliNet, TlsAndTokensGiveTheSameRows) {
  const auto cert = self_signed("IP:127.0.0.1");
  server::ServerConfig cfg;
  cfg.tls_certificate_file = cert->cert.string();
  cfg.tls_key_file = cert->key.string();
  auto auth = server::Credentials::parse("control 0123456789abcdef0123456789abcdef\n", "auth");
  ASSERT_TRUE(auth.ok());
  cfg.credentials = std::make_shared<const server::Credentials>(std::move(auth).value());
  cfg.anonymous = server::Role::kRead;
  TestServer tls(cfg);
  TestServer plain;
  const std::string query = "query walk --frames 0:20 --roots l_hand --relative-to head";
  const CommandRun expected = gmr(query + " --port " + std::to_string(plain.port()));
  ASSERT_EQ(expected.status, 0) << expected.out;
  const std::string secure = " --port " + std::to_string(tls.port()) + " --tls-ca '" + cert->cert.string() + "'";
  const CommandRun with_token = gmr(query + secure + " --token 0123456789abcdef0123456789abcdef");
  ASSERT_EQ(with_token.status, 0) << with_token.out;
  EXPECT_EQ(with_token.out, expected.out);
  const CommandRun from_env =
      gmr("GMR_TOKEN=0123456789abcdef0123456789abcdef " + std::string(GMR_CLI_PATH) + " " + query + secure,
          /*prefix_binary=*/false);
  ASSERT_EQ(from_env.status, 0) << from_env.out;
  EXPECT_EQ(from_env.out, expected.out);
  const CommandRun anonymous = gmr(query + secure);
  EXPECT_EQ(anonymous.status, 1);
  EXPECT_EQ(anonymous.out.rfind("gmr: PERMISSION_DENIED: this connection's role is 'read'", 0), 0u) << anonymous.out;
  EXPECT_EQ(std::count(anonymous.out.begin(), anonymous.out.end(), '\n'), 1);
  const CommandRun wrong = gmr(query + secure + " --token 0123456789abcdef0123456789abcdee");
  EXPECT_EQ(wrong.status, 1);
  EXPECT_NE(wrong.out.find("UNAUTHENTICATED: the server does not know this token"), std::string::npos) << wrong.out;
  const CommandRun untrusted = gmr("ls --tls --port " + std::to_string(tls.port()));
  EXPECT_EQ(untrusted.status, 1);
  EXPECT_NE(untrusted.out.find("certificate verify failed"), std::string::npos) << untrusted.out;
}

}  // namespace
}  // namespace gmr::test
