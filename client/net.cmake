# gmr::client (the C++ client library) and gmr-load (the load tester).
# Included from client/CMakeLists.txt when GMR_BUILD_NET is ON.
find_package(Boost 1.74 REQUIRED COMPONENTS system)
find_package(spdlog CONFIG REQUIRED)

add_library(gmr_client STATIC
  ${CMAKE_CURRENT_LIST_DIR}/include/gmr/client/client.h
  ${CMAKE_CURRENT_LIST_DIR}/src/client.cpp
)
add_library(gmr::client ALIAS gmr_client)
target_include_directories(gmr_client PUBLIC $<BUILD_INTERFACE:${CMAKE_CURRENT_LIST_DIR}/include>)
target_link_libraries(gmr_client PUBLIC gmr::gmr gmr::wire PRIVATE Boost::system Threads::Threads)
gmr_set_warnings(gmr_client)

if(EXISTS ${CMAKE_CURRENT_LIST_DIR}/load/main.cpp)
  add_executable(gmr_load ${CMAKE_CURRENT_LIST_DIR}/load/main.cpp)
  set_target_properties(gmr_load PROPERTIES OUTPUT_NAME gmr-load RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bin)
  target_link_libraries(gmr_load PRIVATE gmr::client CLI11::CLI11 Threads::Threads)
  gmr_set_warnings(gmr_load)
endif()
