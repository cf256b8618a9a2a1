# NET area: the wire library (framing, UDP fragments, frame encoding) and
# loopback server + client tests (127.0.0.1, port 0, no sleeps).
if(TARGET gmr_server AND TARGET gmr_client)
  gmr_add_test(gmr_net_tests SANITIZE
    net/wire_test.cpp
    net/net_test_util.cpp
    net/server_positions_test.cpp
    net/server_float_path_test.cpp
    net/server_bad_input_test.cpp
    net/server_streaming_test.cpp
    net/library_test.cpp
  )
  find_package(spdlog CONFIG REQUIRED)
  target_link_libraries(gmr_net_tests PRIVATE gmr::server gmr::client gmr::wire spdlog::spdlog)
endif()

# `gmr query` must print what `gmr positions` prints: run both commands.
if(TARGET gmr_net_tests AND TARGET gmr_cli)
  target_sources(gmr_net_tests PRIVATE net/cli_net_test.cpp)
  target_compile_definitions(gmr_net_tests PRIVATE GMR_CLI_PATH="$<TARGET_FILE:gmr_cli>")
  add_dependencies(gmr_net_tests gmr_cli)
endif()
