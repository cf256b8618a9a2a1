#include "test_data.h"

#include <algorithm>
#include <cmath>
#include <cctype>
#include <cstdlib>
#include <iterator>
#include <string_view>
#include <system_error>

#include <unistd.h>

namespace gmr::test {
namespace fs = std::filesystem;

static fs::path source_dir() {
  if (const char* s = std::getenv("GMR_SOURCE_DIR"); s != nullptr && *s != '\0') return s;
  return fs::current_path();
}

fs::path data_dir() {
  if (const char* d = std::getenv("GMR_DATA_DIR"); d != nullptr && *d != '\0') return d;
  return (source_dir() / ".." / "shared" / "data").lexically_normal();
}

bool have_data() { return fs::is_directory(data_dir() / "bvh"); }

bool in_ci() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string(ci) == "true";
}

namespace {

// How many files of each kind the shared corpus holds (../shared/data, see
// its PROVENANCE.md). A loop over data_files() covers exactly this many, so
// a renamed or emptied folder fails the test instead of passing it silently.
struct CorpusCount {
  std::string_view sub, ext;
  std::size_t files;
};
constexpr CorpusCount kCorpus[] = {
    {"bvh", ".bvh", 44},       {"bvh/parser_fixtures", ".bvh", 7},
    {"bvh/bandai", ".bvh", 6}, {"malformed", ".bvh", 7},
    {"asfamc", ".asf", 7},     {"asfamc", ".amc", 9},
    {"c3d", ".c3d", 6},        {"trc", ".trc", 9},
};

}  // namespace

std::size_t expected_data_files(const std::string& sub, const std::string& ext) {
  for (const auto& c : kCorpus) {
    if (c.sub == sub && c.ext == ext) return c.files;
  }
  ADD_FAILURE() << "data_files(\"" << sub << "\", \"" << ext << "\"): no expected count in tests/support";
  return 0;
}

std::vector<fs::path> data_files(const std::string& sub, const std::string& ext) {
  std::vector<fs::path> out;
  const fs::path root = data_dir() / sub;
  if (!have_data()) return out;  // the test skips (GMR_REQUIRE_DATA) or fails in CI
  if (fs::is_directory(root)) {
    for (const auto& e : fs::recursive_directory_iterator(root)) {
      if (!e.is_regular_file()) continue;
      std::string x = e.path().extension().string();
      std::transform(x.begin(), x.end(), x.begin(), [](unsigned char c) { return std::tolower(c); });
      if (x == ext) out.push_back(e.path());
    }
  }
  std::sort(out.begin(), out.end());
  const std::size_t want = expected_data_files(sub, ext);
  if (out.size() != want) {
    ADD_FAILURE() << root.string() << ": " << out.size() << " " << ext << " files found, the corpus holds " << want;
  }
  return out;
}

fs::path data_file(const std::string& relative) { return data_dir() / relative; }

TempDir::TempDir() {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  path = fs::temp_directory_path() / ("gmr_test_" + std::to_string(::getpid()) + "_" +
                                      (info ? std::string(info->test_suite_name()) + "_" + info->name() : "none"));
  fs::remove_all(path);
  fs::create_directories(path);
}

TempDir::~TempDir() {
  std::error_code ec;
  fs::remove_all(path, ec);
}

std::size_t TempDir::entries() const {
  return static_cast<std::size_t>(std::distance(fs::directory_iterator(path), fs::directory_iterator{}));
}

PositionDiff compare_positions(std::span<const Eigen::Vector3d> a, std::span<const Eigen::Vector3d> b,
                               std::size_t joints) {
  PositionDiff d;
  const std::size_t n = std::min(a.size(), b.size());
  for (std::size_t i = 0; i < n; ++i) {
    const double e = (a[i] - b[i]).norm();
    if (!(e <= d.max_error)) {  // also catches NaN
      d.max_error = std::isnan(e) ? INFINITY : e;
      d.frame = joints ? i / joints : 0;
      d.joint = joints ? static_cast<int>(i % joints) : -1;
    }
  }
  return d;
}

std::vector<Eigen::Vector3d> compose_locals(const Skeleton& skeleton, std::span<const Eigen::Quaterniond> q,
                                            std::span<const Eigen::Vector3d> t) {
  std::vector<Eigen::Vector3d> p(skeleton.size());
  std::vector<Eigen::Matrix3d> o(skeleton.size());
  for (int j = 0; j < static_cast<int>(skeleton.size()); ++j) {
    const auto u = static_cast<std::size_t>(j);
    const int parent = skeleton.joint(j).parent;
    if (parent == kNoParent) {
      o[u] = q[u].toRotationMatrix();
      p[u] = t[u];
    } else {
      const auto pu = static_cast<std::size_t>(parent);
      o[u] = o[pu] * q[u].toRotationMatrix();
      p[u] = p[pu] + o[pu] * t[u];
    }
  }
  return p;
}

}  // namespace gmr::test
