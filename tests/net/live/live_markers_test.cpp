// Live marker sources (docs/protocol.md, "Live markers"): a publisher sends
// CMU 01_01's labelled markers and the cmu41 model; the server calibrates on
// the first two seconds, then serves the solved skeleton as a live source.
// Subscribers get, frame for frame, the positions of the same take solved
// frame by frame on the same calibration (gmr convert --calibrate-seconds 2);
// with markers dropped at random the joints stay near them and the drops are
// counted; bad announcements and frames are refused and counted.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <future>
#include <limits>
#include <map>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "gmr/kinematics/forward_kinematics.h"
#include "gmr/markers/marker_frames.h"
#include "gmr/markers/marker_model.h"
#include "gmr/markers/markers.h"
#include "live_test_util.h"
#include "net_test_util.h"
#include "recording_outbox.h"
#include "server_parts.h"
#include "test_data.h"

namespace gmr::test {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct Take {
  MarkerTrajectories markers;
  std::size_t calibration = 0;  // frames
  Motion solved;                // frame by frame on that calibration
};

const Take& take() {
  static const Take t = [] {
    Take out;
    auto m = load_markers(data_file("c3d/cmu_01_01.c3d"));
    EXPECT_TRUE(m.ok());
    if (!m.ok()) return out;
    out.markers = std::move(m).value();
    out.calibration = static_cast<std::size_t>(2 * out.markers.frame_rate);
    // The frames the tests publish: the calibration and 120 more.
    MarkerTrajectories& mk = out.markers;
    mk.frame_count = std::min(mk.frame_count, out.calibration + 120);
    mk.positions.resize(mk.frame_count * mk.marker_count() * 3);
    mk.residuals.clear();
    auto model = builtin_marker_model("cmu41");
    auto solved = solve_marker_frames(out.markers, *model, 0, out.calibration);
    EXPECT_TRUE(solved.ok()) << solved.error().to_string();
    if (solved.ok()) out.solved = std::move(solved).value();
    return out;
  }();
  return t;
}

// What a subscription received: world positions by frame index.
struct Received {
  std::mutex mutex;
  std::map<std::uint64_t, std::vector<Eigen::Vector3d>> frames;
  std::vector<std::string> joints;
  Latch<client::SubscriptionEnd> end;
};

client::MarkerPublishOptions options(const std::string& name) {
  client::MarkerPublishOptions o;
  o.name = name;
  o.frame_time = 1.0 / take().markers.frame_rate;
  o.model = "cmu41";
  o.calibration_seconds = 2.0;
  o.units = take().markers.units;
  return o;
}

std::span<const double> frame_of(std::size_t f) {
  const std::size_t row = take().markers.marker_count() * 3;
  return std::span<const double>(take().markers.positions).subspan(f * row, row);
}

// Frame `f` of the take with the positions of markers `swap` exchanged
// (none when they are the same marker).
std::vector<double> frame_swapped(std::size_t f, std::pair<std::size_t, std::size_t> swap) {
  std::vector<double> frame(frame_of(f).begin(), frame_of(f).end());
  for (std::size_t k = 0; k < 3 && swap.first != swap.second; ++k) {
    std::swap(frame[3 * swap.first + k], frame[3 * swap.second + k]);
  }
  return frame;
}

// Publishes frames [begin, end) of the take, one per 2 ms (8 ms in a
// sanitized build), markers `swap` exchanged, dropping each present marker
// with probability `drop`; returns the points sent missing (the take's and the dropped).
std::size_t publish(client::Client& c, std::uint32_t id, std::size_t begin, std::size_t end, double drop,
                    std::mt19937& random, std::pair<std::size_t, std::size_t> swap = {0, 0}) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const auto period = std::chrono::microseconds(kSlowBuild ? 8000 : 2000);
  const auto start = std::chrono::steady_clock::now();
  std::size_t missing = 0;
  for (std::size_t f = begin; f < end; ++f) {
    std::this_thread::sleep_until(start + period * static_cast<std::int64_t>(f - begin));
    std::vector<double> frame = frame_swapped(f, swap);
    for (std::size_t m = 0; m < frame.size() / 3; ++m) {
      if (std::isnan(frame[3 * m])) {
        ++missing;
      } else if (drop > 0 && uniform(random) < drop) {
        frame[3 * m] = frame[3 * m + 1] = frame[3 * m + 2] = kNaN;
        ++missing;
      }
    }
    EXPECT_TRUE(c.publish_marker_frame(id, frame).ok());
  }
  return missing;
}

// A client with the publish token whose requests wait up to 30 s: the
// calibration takes seconds in a sanitized build under load, and the
// publisher's requests after it wait unread until it is done.
std::unique_ptr<client::Client> publisher(TestServer& server) {
  client::ClientOptions o;
  o.auth_token = kPublishToken;
  o.timeout = std::chrono::seconds(30);
  return server.connect(o);
}

// Waits (a round trip at a time, up to 30 s) until the server lists `name`:
// a publication is listed once its calibration is back from the edit thread,
// seconds in a sanitized build, after the calibrations queued before it.
bool listed(client::Client& c, const std::string& name) {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (std::chrono::steady_clock::now() < give_up) {
    auto list = c.list_motions();
    if (list.ok() && std::ranges::any_of(*list, [&](const auto& m) { return m.name == name; })) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return false;
}

void subscribe(client::Client& c, const std::string& motion, Received& r) {
  auto view = c.create_view(motion);
  ASSERT_TRUE(view.ok()) << view.error().to_string();
  client::SubscribeOptions so;
  so.float64 = true;
  so.max_staleness = std::chrono::milliseconds(0);
  auto sub = c.subscribe(
      view->id, so,
      [&r](const client::ReceivedFrame& f) {
        std::lock_guard lock(r.mutex);
        r.frames[f.frame_index] = f.positions;
      },
      [&r](const client::SubscriptionEnd& e) { r.end.set(e); });
  ASSERT_TRUE(sub.ok()) << sub.error().to_string();
  std::lock_guard lock(r.mutex);
  for (int j : sub->joints) r.joints.push_back(sub->skeleton.joint(j).name);
}

// Per (frame, joint) distances of what arrived from the take solved frame by
// frame (millimetres).
std::vector<double> distances(Received& r) {
  const Motion& want = take().solved;
  const auto positions = compute_positions(want);
  const std::size_t n = want.skeleton.size();
  std::vector<double> d;
  std::lock_guard lock(r.mutex);
  for (const auto& [index, got] : r.frames) {
    EXPECT_LT(index, want.frame_count);
    EXPECT_EQ(got.size(), r.joints.size());
    if (index >= want.frame_count || got.size() != r.joints.size()) continue;
    for (std::size_t k = 0; k < got.size(); ++k) {
      const int j = want.skeleton.find(r.joints[k]);
      EXPECT_GE(j, 0) << r.joints[k];
      if (j >= 0) d.push_back((got[k] - positions[index * n + static_cast<std::size_t>(j)]).norm());
    }
  }
  return d;
}

double median(std::vector<double> v) {
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

TEST(LiveMarkers, SubscribersGetTheTakeSolvedFrameByFrameAndDropsAreCounted) {
  GMR_REQUIRE_DATA();
  ASSERT_GT(take().solved.frame_count, 0u);
  const std::size_t calibration = take().calibration, served = 120;
  Received full, dropped;  // declared before the clients: their callbacks write here
  TestServer server(live_config());
  auto pub = connect_as(server, kPublishToken);
  auto sub = connect_as(server, kControlToken);
  ASSERT_TRUE(pub && sub);
  std::mt19937 random(20261127);
  const std::vector<std::string>& names = take().markers.names;
  auto a = pub->publish_markers(names, options("lab"));
  auto b = pub->publish_markers(names, options("lab dropped"));
  ASSERT_TRUE(a.ok()) << a.error().to_string();
  ASSERT_TRUE(b.ok()) << b.error().to_string();
  // Not served while it calibrates.
  publish(*pub, a->id, 0, calibration - 1, 0.0, random);
  ASSERT_TRUE(pub->list_motions().ok());
  EXPECT_FALSE(sub->create_view("lab").ok());
  publish(*pub, a->id, calibration - 1, calibration, 0.0, random);
  publish(*pub, b->id, 0, calibration, 0.0, random);
  ASSERT_TRUE(listed(*sub, "lab") && listed(*sub, "lab dropped"));
  subscribe(*sub, "lab", full);
  subscribe(*sub, "lab dropped", dropped);
  const auto before = sub->stats().value();
  publish(*pub, a->id, calibration, calibration + served, 0.0, random);
  const std::size_t missing = publish(*pub, b->id, calibration, calibration + served, 0.1, random);
  ASSERT_TRUE(pub->unpublish(a->id).ok());
  ASSERT_TRUE(pub->unpublish(b->id).ok());
  ASSERT_TRUE(full.end.wait().has_value());
  ASSERT_TRUE(dropped.end.wait().has_value());
  EXPECT_TRUE(pub->take_errors().empty());
  const auto after = sub->stats().value();

  // Every frame arrived or was counted; what arrived is the take solved frame
  // by frame, within 1 mm.
  const auto d = distances(full);
  const std::size_t least = kSlowBuild ? served / 4 : served / 2;
  {
    std::lock_guard lock(full.mutex);
    EXPECT_GE(full.frames.size(), least);
    EXPECT_EQ(full.joints.size(), take().solved.skeleton.size());
    for (const auto& [index, _] : full.frames) EXPECT_GE(index, calibration);
  }
  ASSERT_FALSE(d.empty());
  EXPECT_LE(*std::max_element(d.begin(), d.end()), 1.0);
  // One point in ten dropped: near the full solve, and every missing point
  // of a solved frame counted.
  const auto dd = distances(dropped);
  ASSERT_FALSE(dd.empty());
  std::printf(
      "[ figures  ] live markers: %zu frames within %.2g mm of the take solved frame by frame; with %zu points "
      "missing, %zu frames %.1f mm median off it, %llu part poses held\n",
      d.size() / full.joints.size(), *std::max_element(d.begin(), d.end()), missing, dd.size() / dropped.joints.size(),
      median(dd), static_cast<unsigned long long>(after.live_marker_parts_held - before.live_marker_parts_held));
  EXPECT_LE(median(dd), 10.0);
  std::size_t take_missing = 0;  // in the full publication's served frames
  for (std::size_t f = calibration; f < calibration + served; ++f) {
    for (std::size_t m = 0; m < names.size(); ++m) take_missing += std::isnan(frame_of(f)[3 * m]) ? 1 : 0;
  }
  EXPECT_LE(after.live_marker_points_missing - before.live_marker_points_missing, take_missing + missing);
  EXPECT_GE(after.live_marker_points_missing - before.live_marker_points_missing, take_missing + missing / 2);
}

// Two labels swapped (a forehead marker and the sternum's) in every served
// frame: each lands far from its part's fit, the outlier rule leaves both
// out, the joints stay near the take's solve, and the server counts what
// the library's solver counts on the same frames.
TEST(LiveMarkers, SwappedLabelsAreLeftOutAsOutliersAndCounted) {
  GMR_REQUIRE_DATA();
  ASSERT_GT(take().solved.frame_count, 0u);
  const std::size_t calibration = take().calibration, served = 120;
  Received swapped;  // declared before the clients: their callbacks write here
  TestServer server(live_config());
  auto pub = publisher(server);
  auto sub = connect_as(server, kControlToken);
  ASSERT_TRUE(pub && sub);
  const std::vector<std::string>& names = take().markers.names;
  const auto index_of = [&](const std::string& label) {
    const auto it = std::ranges::find_if(names, [&](const std::string& n) { return n.ends_with(label); });
    EXPECT_NE(it, names.end()) << label;
    return static_cast<std::size_t>(it - names.begin());
  };
  const std::pair<std::size_t, std::size_t> swap{index_of("LFHD"), index_of("STRN")};
  ASSERT_NE(swap.first, swap.second);
  std::mt19937 random(20261128);
  auto a = pub->publish_markers(names, options("lab swapped"));
  ASSERT_TRUE(a.ok()) << a.error().to_string();
  publish(*pub, a->id, 0, calibration, 0.0, random);
  ASSERT_TRUE(listed(*sub, "lab swapped"));
  subscribe(*sub, "lab swapped", swapped);
  const auto before = sub->stats().value();
  publish(*pub, a->id, calibration, calibration + served, 0.0, random, swap);
  ASSERT_TRUE(pub->unpublish(a->id).ok());  // answered after every frame before it
  ASSERT_TRUE(swapped.end.wait().has_value());
  EXPECT_TRUE(pub->take_errors().empty());
  const auto after = sub->stats().value();

  // The library's solver on the same calibration and frames.
  auto model = builtin_marker_model("cmu41");
  ASSERT_TRUE(model.ok());
  auto solver = MarkerFrameSolver::calibrate(take().markers, *model, 0, calibration);
  ASSERT_TRUE(solver.ok()) << solver.error().to_string();
  const MarkerFrameCounts start = solver->counts();
  for (std::size_t f = calibration; f < calibration + served; ++f) (void)solver->solve(frame_swapped(f, swap));
  const std::size_t outliers = solver->counts().outliers - start.outliers;
  EXPECT_GE(outliers, 2 * served * 9 / 10) << "both swapped points, in nearly every frame";
  EXPECT_EQ(after.live_marker_points_outliers - before.live_marker_points_outliers, outliers);
  EXPECT_EQ(after.live_marker_frames_unsolved - before.live_marker_frames_unsolved,
            solver->counts().refused - start.refused);
  const auto d = distances(swapped);
  ASSERT_FALSE(d.empty());
  std::printf("[ figures  ] live markers, two labels swapped: %zu outliers in %zu frames, joints %.1f mm median off\n",
              outliers, served, median(d));
  EXPECT_LE(median(d), 10.0);
}

// Before, recording a marker publication was refused. Now the server
// records the solved skeleton from its first solved frame, as any live
// source: the file holds every served frame, the take solved frame by frame.
TEST(LiveMarkers, ARecordedMarkerPublicationHoldsTheSolvedFrames) {
  GMR_REQUIRE_DATA();
  ASSERT_GT(take().solved.frame_count, 0u);
  const std::size_t calibration = take().calibration, served = 60;
  TempDir dir;
  server::ServerConfig cfg = live_config();
  cfg.record_dir = dir.path.string();
  std::filesystem::path file;
  {
    TestServer server(cfg);
    auto pub = publisher(server);
    ASSERT_TRUE(pub);
    client::MarkerPublishOptions o = options("lab/recorded");
    o.record = true;
    auto a = pub->publish_markers(take().markers.names, o);
    ASSERT_TRUE(a.ok()) << a.error().to_string();
    file = a->recording;
    EXPECT_EQ(file.parent_path(), dir.path);
    EXPECT_EQ(file.extension(), ".gmrb");
    std::mt19937 random(7);
    publish(*pub, a->id, 0, calibration, 0.0, random);
    ASSERT_TRUE(listed(*pub, "lab/recorded"));  // calibrated
    // Slower than the declared rate: no frame is dropped for it.
    const auto period = std::chrono::milliseconds(12);
    const auto start = std::chrono::steady_clock::now();
    for (std::size_t f = calibration; f < calibration + served; ++f) {
      std::this_thread::sleep_until(start + period * static_cast<std::int64_t>(f - calibration));
      ASSERT_TRUE(pub->publish_marker_frame(a->id, frame_of(f)).ok());
    }
    const Status ended = pub->unpublish(a->id);
    ASSERT_TRUE(ended.ok()) << ended.error().to_string();
    EXPECT_TRUE(pub->take_errors().empty());
    for (int i = 0; i < 1000 && !std::filesystem::exists(file); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  ASSERT_TRUE(std::filesystem::exists(file));
  auto recorded = load_motion(file);
  ASSERT_TRUE(recorded.ok()) << recorded.error().to_string();
  ASSERT_EQ(recorded->frame_count, served);
  const Motion& want = take().solved;
  ASSERT_EQ(recorded->skeleton.size(), want.skeleton.size());
  const std::size_t n = want.skeleton.size();
  const auto got = compute_positions(*recorded);
  const auto expected = compute_positions(want);
  for (std::size_t j = 0; j < n; ++j) {
    EXPECT_EQ(recorded->skeleton.joint(static_cast<int>(j)).name, want.skeleton.joint(static_cast<int>(j)).name);
  }
  double worst = 0;
  for (std::size_t f = 0; f < served; ++f) {
    for (std::size_t j = 0; j < n; ++j) {
      worst = std::max(worst, (got[f * n + j] - expected[(calibration + f) * n + j]).norm());
    }
  }
  EXPECT_LT(worst, 1e-6) << "millimetres";
}

TEST(LiveMarkers, BadAnnouncementsAndFramesAreRefusedNamingWhatAndCounted) {
  GMR_REQUIRE_DATA();
  TestServer server(live_config());
  auto pub = connect_as(server, kPublishToken);
  ASSERT_TRUE(pub);
  std::vector<std::string> names = take().markers.names;
  // The model needs markers the stream does not name: refused, naming them.
  std::vector<std::string> fewer;
  for (const auto& n : names) {
    if (n.find("LKNE") == std::string::npos && n.find("RFIN") == std::string::npos) fewer.push_back(n);
  }
  auto lacking = pub->publish_markers(fewer, options("lacking"));
  ASSERT_FALSE(lacking.ok());
  EXPECT_NE(lacking.error().message.find("needs 2 markers the stream does not name: LKNE, RFIN"), std::string::npos)
      << lacking.error().message;
  auto unknown = options("unknown model");
  unknown.model = "cmu99";
  auto bad_model = pub->publish_markers(names, unknown);
  ASSERT_FALSE(bad_model.ok());
  EXPECT_NE(bad_model.error().message.find("cmu41"), std::string::npos) << bad_model.error().message;
  auto twice = names;
  twice.push_back(names[0]);
  EXPECT_FALSE(pub->publish_markers(twice, options("twice")).ok());

  auto p = pub->publish_markers(names, options("bad frames"));
  ASSERT_TRUE(p.ok()) << p.error().to_string();
  const auto before = pub->stats().value();
  std::vector<double> frame(frame_of(0).begin(), frame_of(0).end());
  frame[4] = std::numeric_limits<double>::infinity();
  ASSERT_TRUE(pub->publish_marker_frame(p->id, frame).ok());
  frame[4] = 1e12;  // 1,000 km
  ASSERT_TRUE(pub->publish_marker_frame(p->id, frame).ok());
  frame.pop_back();
  ASSERT_TRUE(pub->publish_marker_frame(p->id, frame).ok());
  ASSERT_TRUE(pub->list_motions().ok());  // a round trip: the server has read them
  const auto errors = pub->take_errors();
  ASSERT_EQ(errors.size(), 3u);
  EXPECT_NE(errors[0].find("marker \"" + names[1] + "\" has coordinate y = inf"), std::string::npos) << errors[0];
  EXPECT_NE(errors[1].find("beyond 10 km"), std::string::npos) << errors[1];
  EXPECT_NE(errors[2].find("need " + std::to_string(3 * names.size())), std::string::npos) << errors[2];
  EXPECT_EQ(pub->stats().value().live_frames_refused - before.live_frames_refused, 3u);
}

// The calibration (20 ms in Release, seconds under a sanitizer) is computed
// on the edit thread: the frame that completes it returns at once, the
// publisher's requests are not read until it is back, other sessions are
// answered meanwhile; a calibration that fails answers that frame with why;
// a publisher that goes away meanwhile leaves nothing. Without sockets: the
// handler alone, its control loop run by the test.
TEST(LiveMarkers, TheCalibrationRunsOffTheControlLoopWhileThePublishersRequestsWait) {
  GMR_REQUIRE_DATA();
  server::ServerConfig cfg;
  cfg.anonymous = server::Role::kPublish;
  const std::size_t calibration = take().calibration;
  enum class Case { kServed, kFails, kLeaves };
  for (const Case c : {Case::kServed, Case::kFails, Case::kLeaves}) {
    SCOPED_TRACE(c == Case::kServed  ? "served"
                 : c == Case::kFails ? "the calibration fails (no lower-body marker seen)"
                                     : "the publisher leaves while it calibrates");
    ServerParts parts(cfg, test_library());
    std::promise<void> open;
    server::net::post(parts.edit_pool, [gate = open.get_future().share()] { gate.wait(); });  // the edit thread, busy
    RecordedSession pub(parts.services, 1), other(parts.services, 2);
    pb::ClientMessage m;
    pb::Publish& p = *m.mutable_publish();
    p.set_name("lab/off loop");
    p.set_frame_time(1.0 / take().markers.frame_rate);
    p.mutable_markers()->set_model("cmu41");
    p.mutable_markers()->set_units(take().markers.units);
    for (const std::string& name : take().markers.names) p.mutable_markers()->add_names(name);
    const pb::ServerMessage published = pub.ask(m);
    ASSERT_TRUE(published.has_published()) << published.DebugString();
    const std::uint32_t id = published.published().publication_id();
    auto send = [&](std::size_t f) {
      pb::ClientMessage frame;
      frame.set_request_id(100 + f);
      pb::PublishFrame& pf = *frame.mutable_publish_frame();
      pf.set_publication_id(id);
      const auto values = frame_of(f);
      for (std::size_t k = 0; k < values.size(); ++k) {
        const std::string& name = take().markers.names[k / 3];
        const bool lower_body = name.find("KNE") != std::string::npos || name.find("ANK") != std::string::npos;
        const bool missing = std::isnan(values[k - k % 3]) || (c == Case::kFails && lower_body);
        pf.add_values(missing ? 0.0 : values[k]);
        if (missing && k % 3 == 0) pf.add_missing_markers(static_cast<std::uint32_t>(k / 3));
      }
      pub.handler->on_message(frame.SerializeAsString());
    };
    for (std::size_t f = 0; f < calibration; ++f) send(f);
    EXPECT_TRUE(pub.box->replies.empty()) << pub.box->replies.front().DebugString();
    EXPECT_TRUE(pub.box->reading_held) << "the publisher's requests wait for the calibration";
    EXPECT_FALSE(parts.catalog.find("lab/off loop")) << "served before its calibration";
    EXPECT_GT(parts.admission.view_bytes(), 0u) << "the calibration's frames are in the memory budget";
    pb::ClientMessage list;
    list.mutable_list_motions();
    EXPECT_TRUE(other.ask(list).has_motions()) << "another session is answered while it calibrates";
    if (c == Case::kLeaves) pub.handler->on_stop();
    // The edit thread runs the calibration, then this marker; the control
    // loop gets the calibration's outcome, then the marker's.
    std::atomic<bool> done = false;
    open.set_value();
    server::net::post(parts.edit_pool, [&] { server::net::post(parts.io, [&] { done = true; }); });
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (!done && std::chrono::steady_clock::now() < give_up) {
      parts.io.restart();  // the loop stops, and returns at once, when it has nothing to do
      if (parts.io.poll() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ASSERT_TRUE(done);
    if (c != Case::kFails) {
      EXPECT_TRUE(pub.box->replies.empty()) << pub.box->replies.front().DebugString();
    }
    if (c != Case::kServed) {
      EXPECT_FALSE(parts.catalog.find("lab/off loop"));
      EXPECT_EQ(parts.admission.view_bytes(), 0u) << "the calibration's frames are given back";
    }
    if (c == Case::kLeaves) continue;
    EXPECT_FALSE(pub.box->reading_held);
    if (c == Case::kFails) {
      ASSERT_EQ(pub.box->replies.size(), 1u);
      const pb::ServerMessage& r = pub.box->replies.front();
      EXPECT_EQ(r.request_id(), 100 + calibration - 1) << "the frame that completed the calibration";
      EXPECT_EQ(r.error().code(), pb::ERROR_CODE_FAILED_PRECONDITION);
      EXPECT_NE(
          r.error().message().find("the calibration on the first " + std::to_string(calibration) + " frames failed"),
          std::string::npos)
          << r.error().message();
      continue;
    }
    const auto source = parts.catalog.live("lab/off loop");
    ASSERT_TRUE(source);
    EXPECT_EQ(source->latest()->skeleton.size(), take().solved.skeleton.size());
    send(calibration);  // the first frame served
    EXPECT_EQ(source->frames(), calibration + 1) << "served as the take's frame " << calibration;
    EXPECT_TRUE(pub.box->replies.empty()) << pub.box->replies.front().DebugString();
  }
}

}  // namespace
}  // namespace gmr::test
