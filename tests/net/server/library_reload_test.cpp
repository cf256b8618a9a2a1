// Library reload (docs/protocol.md, "Library reload"): while clients stream,
// files under the library folder are added, replaced atomically, written
// slowly, truncated and removed, and the server follows: new motions are
// listed, a replaced one gets a new version and its subscribers an end that
// says why, a file still open for writing is never served, a file that no
// longer reads leaves the last good version in place, a removed one ends its
// streams; /metrics counts it all.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include "gmr/core/file_util.h"
#include "gmr/demo/demo_library.h"
#include "gmr/io/gmr_file.h"
#include "gmr/server/library.h"
#include "gmr/server/library_watch.h"
#include "net_test_util.h"
#include "test_data.h"

namespace gmr::test {
namespace {

namespace fs = std::filesystem;

std::string read_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// Writes `bytes` beside `to` and renames it into place: the way a careful
// tool replaces a file (readers see the old one or the new one, whole).
void write_atomically(const fs::path& to, const std::string& bytes) {
  const fs::path tmp = to.parent_path() / ("." + to.filename().string() + ".tmp");
  {
    std::ofstream out(tmp, std::ios::binary);
    out << bytes;
  }
  fs::rename(tmp, to);
}

// Polls `ok` for up to 10 s.
template <class F>
bool eventually(F ok) {
  for (int i = 0; i < 500; ++i) {
    if (ok()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return false;
}

std::optional<client::MotionInfo> listed(client::Client& c, const std::string& name) {
  auto list = c.list_motions();
  if (!list.ok()) return std::nullopt;
  for (const auto& m : *list) {
    if (m.name == name) return m;
  }
  return std::nullopt;
}

std::string metrics(std::uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(port);
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return {};
  }
  const std::string get = "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n";
  (void)::send(fd, get.data(), get.size(), MSG_NOSIGNAL);
  std::string out;
  char buf[4096];
  for (ssize_t n; (n = ::recv(fd, buf, sizeof buf, 0)) > 0;) out.append(buf, static_cast<std::size_t>(n));
  ::close(fd);
  return out;
}

// Waits until the watcher has made no reload for 300 ms.
void settle(const server::LibraryWatcher& w) {
  std::uint64_t seen = w.reloads();
  for (int quiet = 0; quiet < 15;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    const std::uint64_t now = w.reloads();
    quiet = now == seen ? quiet + 1 : 0;
    seen = now;
  }
}

// A subscription's frames and end, as its callbacks saw them.
struct Watched {
  std::atomic<std::uint64_t> frames{0};
  Latch<std::string> end;
};

std::uint32_t watch(client::Client& c, std::uint32_t view, Watched& w) {
  client::SubscribeOptions so;
  so.loop = true;
  so.rate_hz = 100;
  auto sub = c.subscribe(
      view, so, [&w](const client::ReceivedFrame&) { ++w.frames; },
      [&w](const client::SubscriptionEnd& e) { w.end.set(e.reason); });
  EXPECT_TRUE(sub.ok()) << sub.error().to_string();
  return sub.ok() ? sub->id : 0;
}

TEST(LibraryReload, FilesAddedReplacedWrittenTruncatedAndRemovedWhileStreaming) {
  TempDir dir;
  std::map<std::string, Motion> demo;
  for (auto& m : demo_library()) demo.emplace(m.name, std::move(m.motion));
  for (const char* name : {"walk", "wave", "jump"}) {
    ASSERT_TRUE(write_gmr(demo.at(name), dir.path / (std::string(name) + ".gmr")).ok());
  }
  auto loaded = server::load_library(dir.path);
  ASSERT_TRUE(loaded.ok()) << loaded.error().to_string();
  ASSERT_EQ(loaded->entries.size(), 3u);
  server::ServerConfig cfg;
  cfg.http_port = 0;
  TestServer s(cfg, loaded->entries);
  server::LibraryWatcher::Options options;
  options.dir = dir.path;
  options.settle = std::chrono::milliseconds(50);
  server::LibraryWatcher watcher(s.server, options, loaded->entries);
  ASSERT_EQ(watcher.watch_error(), "");
  // What the callbacks count outlives the client (declared first).
  Watched walking, waving, jumping, hopping;
  auto c = s.connect();
  ASSERT_NE(c, nullptr);
  auto walk = c->create_view("walk");
  auto wave = c->create_view("wave");
  auto jump = c->create_view("jump");
  ASSERT_TRUE(walk.ok() && wave.ok() && jump.ok());
  watch(*c, walk->id, walking);
  watch(*c, wave->id, waving);
  watch(*c, jump->id, jumping);
  ASSERT_TRUE(eventually([&] { return walking.frames > 5 && waving.frames > 5 && jumping.frames > 5; }));
  EXPECT_EQ(listed(*c, "walk")->version, 1u);

  // Added, by an atomic rename.
  write_atomically(dir.path / "hop.gmr", read_bytes(dir.path / "jump.gmr"));
  ASSERT_TRUE(eventually([&] { return listed(*c, "hop").has_value(); })) << "hop.gmr was never served";
  EXPECT_EQ(listed(*c, "hop")->version, 1u);
  EXPECT_EQ(listed(*c, "hop")->source, "hop.gmr");

  // Replaced atomically by another motion: a new version; walk's stream ends
  // saying why, its old view refuses to stream, a new view shows the new file.
  ASSERT_TRUE(write_gmr(demo.at("turn"), dir.path / "turn.gmr.keep").ok());
  write_atomically(dir.path / "walk.gmr", read_bytes(dir.path / "turn.gmr.keep"));
  const auto ended = walking.end.wait(std::chrono::seconds(10));
  ASSERT_TRUE(ended.has_value()) << "walk's subscriber was not told";
  EXPECT_NE(ended->find("motion 'walk' changed on disk (version 1 -> 2)"), std::string::npos) << *ended;
  EXPECT_EQ(listed(*c, "walk")->version, 2u);
  client::SubscribeOptions so;
  auto old = c->subscribe(walk->id, so, [](const client::ReceivedFrame&) {});
  ASSERT_FALSE(old.ok());
  EXPECT_NE(old.error().message.find("FAILED_PRECONDITION: motion 'walk' changed on disk"), std::string::npos)
      << old.error().message;
  auto walk2 = c->create_view("walk");
  ASSERT_TRUE(walk2.ok());
  auto now = c->query(walk2->id, 0, 240);
  ASSERT_TRUE(now.ok()) << now.error().to_string();
  {
    // The new walk is turn's motion, exactly (by name: the same skeleton).
    server::LibraryEntry turn_entry;
    turn_entry.name = "turn";
    turn_entry.source = "builtin";
    turn_entry.motion = std::make_shared<const Motion>(demo.at("turn"));
    TestServer reference({}, {turn_entry});
    auto r = reference.connect();
    auto turn = r->create_view("turn");
    ASSERT_TRUE(turn.ok());
    auto expected = r->query(turn->id, 0, 240);
    ASSERT_TRUE(expected.ok());
    ASSERT_EQ(now->positions.size(), expected->positions.size());
    for (std::size_t i = 0; i < now->positions.size(); ++i) ASSERT_EQ(now->positions[i], expected->positions[i]) << i;
  }

  // Written slowly: never served half; served whole once closed. (First the
  // reloads the edits above caused are let finish.)
  settle(watcher);
  Motion long_walk = demo.at("walk");
  const fs::path source = dir.path / "half.source";
  ASSERT_TRUE(write_gmr(long_walk, source).ok());
  const std::string whole = read_bytes(source);
  fs::remove(source);
  {
    std::ofstream slow(dir.path / "half.gmr", std::ios::binary);
    slow << whole.substr(0, whole.size() / 2);
    slow.flush();
    const std::uint64_t before = watcher.reloads();
    watcher.reload();
    ASSERT_TRUE(eventually([&] { return watcher.reloads() > before; }));
    EXPECT_FALSE(listed(*c, "half").has_value()) << "half a file was served";
    slow << whole.substr(whole.size() / 2);
  }
  ASSERT_TRUE(eventually([&] { return listed(*c, "half").has_value(); })) << "half.gmr was never served";
  EXPECT_EQ(listed(*c, "half")->frame_count, long_walk.frame_count);

  // Truncated in place (open, write half, close): it no longer reads, so the
  // last good version stays, and its streams go on.
  auto hop = c->create_view("hop");
  ASSERT_TRUE(hop.ok());
  watch(*c, hop->id, hopping);
  {
    const std::string bytes = read_bytes(dir.path / "hop.gmr");
    std::ofstream cut(dir.path / "hop.gmr", std::ios::binary | std::ios::trunc);
    cut << bytes.substr(0, bytes.size() / 2);
  }
  const std::uint64_t before = watcher.reloads();
  ASSERT_TRUE(eventually([&] { return watcher.reloads() > before; }));
  const std::uint64_t hop_frames = hopping.frames;
  ASSERT_TRUE(eventually([&] { return hopping.frames > hop_frames + 5; })) << "hop's stream stopped";
  EXPECT_FALSE(hopping.end.wait(std::chrono::milliseconds(10)).has_value());
  EXPECT_EQ(listed(*c, "hop")->version, 1u);

  // Removed: its streams end, saying so; it leaves the list.
  fs::remove(dir.path / "wave.gmr");
  const auto gone = waving.end.wait(std::chrono::seconds(10));
  ASSERT_TRUE(gone.has_value()) << "wave's subscriber was not told";
  EXPECT_NE(gone->find("motion 'wave' was removed from the library"), std::string::npos) << *gone;
  EXPECT_FALSE(listed(*c, "wave").has_value());

  // jump was never touched: its stream never ended.
  const std::uint64_t jumped = jumping.frames;
  ASSERT_TRUE(eventually([&] { return jumping.frames > jumped + 5; }));
  EXPECT_FALSE(jumping.end.wait(std::chrono::milliseconds(10)).has_value());

  const std::string text = metrics(s.server.http_port());
  EXPECT_NE(text.find("gmr_library_changes_total{change=\"added\"} 2"), std::string::npos) << text;
  EXPECT_NE(text.find("gmr_library_changes_total{change=\"changed\"} 1"), std::string::npos) << text;
  EXPECT_NE(text.find("gmr_library_changes_total{change=\"removed\"} 1"), std::string::npos) << text;
  EXPECT_NE(text.find("gmr_library_reloads_total"), std::string::npos) << text;
}

// The stamp decides what is read again: a reload of an unchanged folder reads
// nothing and keeps every version; a file open for writing keeps its entry.
TEST(LibraryReload, OnlyChangedFilesAreReadAgain) {
  TempDir dir;
  for (auto& m : demo_library()) ASSERT_TRUE(write_gmr(m.motion, dir.path / (m.name + ".gmr")).ok());
  auto first = server::load_library(dir.path);
  ASSERT_TRUE(first.ok());
  const std::size_t n = first->entries.size();
  ASSERT_GE(n, 4u);
  auto again = server::reload_library(dir.path, first->entries, {});
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->reused, n);
  ASSERT_EQ(again->entries.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(again->entries[i].motion, first->entries[i].motion) << "read again: " << again->entries[i].name;
    EXPECT_EQ(again->entries[i].version, 1u);
  }
  // walk rewritten (another size), wave being written, turn gone.
  for (auto& m : demo_library()) {
    if (m.name == "jump") {
      ASSERT_TRUE(write_gmr(m.motion, dir.path / "walk.gmr").ok());  // another size
    }
  }
  fs::remove(dir.path / "turn.gmr");
  auto third = server::reload_library(dir.path, again->entries, {dir.path / "wave.gmr"});
  ASSERT_TRUE(third.ok());
  EXPECT_EQ(third->kept_back, 1u);
  EXPECT_EQ(third->reused, n - 3);
  std::map<std::string, std::uint32_t> versions;
  for (const auto& e : third->entries) versions[e.name] = e.version;
  EXPECT_EQ(versions.count("turn"), 0u);
  EXPECT_EQ(versions.at("walk"), 2u);
  EXPECT_EQ(versions.at("wave"), 1u);
}

// A units sidecar gives a BVH or .gmr its unit at load; adding, changing or
// breaking one counts as a change of the motions it covers (their stamps
// include it): a new unit is a new version, a broken one is rejected with its
// line and the motion keeps its last version.
TEST(LibraryReload, AUnitsSidecarSetsTheUnitAndItsChangesReload) {
  TempDir dir;
  for (auto& m : demo_library()) ASSERT_TRUE(write_gmr(m.motion, dir.path / (m.name + ".gmr")).ok());
  auto units = [](const server::LibraryLoad& l) {
    std::map<std::string, std::pair<double, std::uint32_t>> u;
    for (const auto& e : l.entries) u[e.name] = {e.metres_per_unit, e.version};
    return u;
  };
  auto first = server::load_library(dir.path);
  ASSERT_TRUE(first.ok());
  EXPECT_EQ(units(*first).at("walk"), (std::pair<double, std::uint32_t>{0.0, 1}));
  ASSERT_TRUE(write_file_atomic(dir.path / "folder.units", "cm\n").ok());
  ASSERT_TRUE(write_file_atomic(dir.path / "walk.units", "in\n").ok());
  auto second = server::reload_library(dir.path, first->entries, {});
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(second->reused, 0u) << "every motion of the folder is covered by folder.units";
  EXPECT_EQ(units(*second).at("walk"), (std::pair<double, std::uint32_t>{0.0254, 2}));
  EXPECT_EQ(units(*second).at("wave"), (std::pair<double, std::uint32_t>{0.01, 2}));
  ASSERT_TRUE(write_file_atomic(dir.path / "walk.units", "inchs\n").ok());
  auto third = server::reload_library(dir.path, second->entries, {});
  ASSERT_TRUE(third.ok());
  EXPECT_EQ(third->kept_back, 1u);
  EXPECT_EQ(units(*third).at("walk"), (std::pair<double, std::uint32_t>{0.0254, 2})) << "kept as it was";
  EXPECT_EQ(units(*third).at("wave"), (std::pair<double, std::uint32_t>{0.01, 2}));
  ASSERT_EQ(third->rejected.size(), 1u);
  EXPECT_EQ(third->rejected[0].path, dir.path / "walk.gmr");
  EXPECT_NE(third->rejected[0].reason.find("walk.units:1:"), std::string::npos) << third->rejected[0].reason;
  EXPECT_NE(third->rejected[0].reason.find("inchs is not a unit"), std::string::npos) << third->rejected[0].reason;
}

}  // namespace
}  // namespace gmr::test
