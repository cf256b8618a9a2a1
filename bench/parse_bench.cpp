// Loading motions: BVH text, GMR text and the .gmrb binary format, in bytes
// per second of input (bytes_per_second counter). The text is in memory (no
// disk time); .gmrb is measured from memory (parse_gmrb) and from a file in
// the page cache (read_gmrb, one bulk read). A 64x repetition of CMU 01_01
// (176k frames, ~135 MB as .gmrb) shows the bulk rate of large files.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <string>
#include <vector>

#include "bench_data.h"
#include "gmr/core/file_util.h"
#include "gmr/io/gmr_file.h"
#include "gmr/io/gmrb.h"

namespace gmr::bench {
namespace {

const std::string& bvh_text() {
  static const std::string text = [] {
    auto t = read_file(main_bvh());
    if (!t) die(t.error().to_string());
    return std::move(*t);
  }();
  return text;
}

// CMU 01_01 as GMR, its frames repeated `times`.
Motion repeated_gmr(std::size_t times) {
  auto gmr = to_pre_rotation(load_main_bvh());
  if (!gmr) die(gmr.error().to_string());
  Motion m = std::move(*gmr);
  const std::vector<double> one = m.values;
  for (std::size_t i = 1; i < times; ++i) m.values.insert(m.values.end(), one.begin(), one.end());
  m.frame_count *= times;
  return m;
}

void BM_ParseBvh(benchmark::State& state) {
  const std::string& text = bvh_text();
  for (auto _ : state) {
    auto m = parse_bvh(text, "01_01.bvh");
    if (!m) die(m.error().to_string());
    benchmark::DoNotOptimize(m->values.data());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * text.size()));
}
BENCHMARK(BM_ParseBvh)->Name("parse/bvh_cmu_01_01")->Unit(benchmark::kMillisecond);

void BM_ParseBvhCorpus(benchmark::State& state) {
  std::vector<std::string> texts;
  std::size_t bytes = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(data_dir() / "bvh")) {
    if (e.path().extension() != ".bvh") continue;
    auto t = read_file(e.path());
    if (!t) die(t.error().to_string());
    bytes += t->size();
    texts.push_back(std::move(*t));
  }
  for (auto _ : state) {
    for (const auto& t : texts) {
      auto m = parse_bvh(t, "corpus.bvh");
      benchmark::DoNotOptimize(m.ok());
    }
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * bytes));
  state.SetLabel(std::to_string(texts.size()) + " files");
}
BENCHMARK(BM_ParseBvhCorpus)->Name("parse/bvh_corpus")->Unit(benchmark::kMillisecond);

void BM_ParseGmr(benchmark::State& state) {
  static const std::string text = format_gmr(repeated_gmr(1)).value();
  for (auto _ : state) {
    auto m = parse_gmr(text, "01_01.gmr");
    if (!m) die(m.error().to_string());
    benchmark::DoNotOptimize(m->values.data());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * text.size()));
}
BENCHMARK(BM_ParseGmr)->Name("parse/gmr_cmu_01_01")->Unit(benchmark::kMillisecond);

void BM_ParseGmrb(benchmark::State& state) {
  const std::string bytes = format_gmrb(repeated_gmr(static_cast<std::size_t>(state.range(0)))).value();
  for (auto _ : state) {
    auto m = parse_gmrb(bytes, "mem.gmrb");
    if (!m) die(m.error().to_string());
    benchmark::DoNotOptimize(m->values.data());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * bytes.size()));
}
BENCHMARK(BM_ParseGmrb)->Name("parse/gmrb_memory")->ArgName("repeat")->Arg(1)->Arg(64)->Unit(benchmark::kMillisecond);

void BM_ReadGmrb(benchmark::State& state) {
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() / ("gmr_parse_bench_" + std::to_string(state.range(0)) + ".gmrb");
  if (!write_gmrb(repeated_gmr(static_cast<std::size_t>(state.range(0))), path).ok())
    die("cannot write " + path.string());
  const auto size = std::filesystem::file_size(path);
  for (auto _ : state) {
    auto m = read_gmrb(path);
    if (!m) die(m.error().to_string());
    benchmark::DoNotOptimize(m->values.data());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * size));
  std::filesystem::remove(path);
}
BENCHMARK(BM_ReadGmrb)->Name("read/gmrb_file")->ArgName("repeat")->Arg(1)->Arg(64)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace gmr::bench

BENCHMARK_MAIN();
