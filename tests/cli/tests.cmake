# The built `gmr` command on real and malformed files: exit codes, the CSV
# contract, the one-line error (files, operations, ASF/AMC, bench). Only when the
# command is built.
if(TARGET gmr_cli)
  gmr_add_test(gmr_cli_tests
    cli/cli_test_util.cpp
    cli/cli_files_test.cpp
    cli/cli_ops_test.cpp
    cli/cli_asf_test.cpp
    cli/cli_bench_test.cpp
    cli/cli_markers_test.cpp
  )
  target_include_directories(gmr_cli_tests PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/cli)
  target_compile_definitions(gmr_cli_tests PRIVATE GMR_CLI_PATH="$<TARGET_FILE:gmr_cli>")
  add_dependencies(gmr_cli_tests gmr_cli)
  find_package(nlohmann_json 3 REQUIRED)  # reads `gmr bench fk --json`
  target_link_libraries(gmr_cli_tests PRIVATE nlohmann_json::nlohmann_json)
endif()
