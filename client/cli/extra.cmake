# Extra links of the `gmr` command.
# NET: ls, skeleton, query, stream need the client library (GMR_BUILD_NET).
if(TARGET gmr_client)
  target_link_libraries(gmr_cli PRIVATE gmr::client)
  target_compile_definitions(gmr_cli PRIVATE GMR_WITH_NET=1)
endif()
# PERF: `gmr bench fk --json` writes JSON with nlohmann-json (header-only).
find_package(nlohmann_json 3 REQUIRED)
target_link_libraries(gmr_cli PRIVATE nlohmann_json::nlohmann_json)
