# Google Benchmark programs for the kernels and the parsers (PERF area).
# Run from the repository root so ../shared/data resolves (or set GMR_DATA_DIR):
#   build/bin/gmr_fk_bench    build/bin/gmr_parse_bench
find_package(benchmark REQUIRED)
foreach(name fk parse)
  add_executable(gmr_${name}_bench ${name}_bench.cpp bench_data.h)
  target_link_libraries(gmr_${name}_bench PRIVATE gmr::gmr benchmark::benchmark)
  target_compile_definitions(gmr_${name}_bench PRIVATE GMR_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
  target_compile_options(gmr_${name}_bench PRIVATE -Wno-missing-field-initializers)
  set_target_properties(gmr_${name}_bench PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bin)
  gmr_set_warnings(gmr_${name}_bench)
endforeach()
