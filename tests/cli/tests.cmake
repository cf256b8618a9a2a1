# Runs the built `gmr` command on real and malformed files (exit codes, CSV
# shape, the one-line error). Only when the command is built.
if(TARGET gmr_cli)
  gmr_add_test(gmr_cli_tests cli/cli_files_test.cpp)
  target_compile_definitions(gmr_cli_tests PRIVATE GMR_CLI_PATH="$<TARGET_FILE:gmr_cli>")
  add_dependencies(gmr_cli_tests gmr_cli)
endif()
# The operation commands and the view options of `gmr positions` (OPS area).
if(TARGET gmr_cli)
  gmr_add_test(gmr_cli_ops_tests cli/cli_ops_test.cpp)
  target_compile_definitions(gmr_cli_ops_tests PRIVATE GMR_CLI_PATH="$<TARGET_FILE:gmr_cli>")
  add_dependencies(gmr_cli_ops_tests gmr_cli)
endif()
# ASF/AMC through the command (ASF area).
if(TARGET gmr_cli)
  gmr_add_test(gmr_cli_asf_tests cli/cli_asf_test.cpp)
  target_compile_definitions(gmr_cli_asf_tests PRIVATE GMR_CLI_PATH="$<TARGET_FILE:gmr_cli>")
  add_dependencies(gmr_cli_asf_tests gmr_cli)
endif()
