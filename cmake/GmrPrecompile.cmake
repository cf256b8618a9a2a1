# Precompiled headers: the system headers most of a target's files include
# (the standard library and Eigen; Boost.Asio, spdlog and protobuf in the
# networked code; GoogleTest in the tests) are parsed once per target, not
# once per file. Parsing them was a quarter of compiling a server file
# (GCC, -O3), and every CI run builds the server and its tests three times
# (Release, ASan, TSan). Through one, GCC 12 reports some warnings from the
# standard library's inlined code that it keeps quiet without: one such
# -Warray-bounds false positive (an Error moved into a Result) was written
# another way.
#
# Only system headers go in, never gmr's own, so a file still has to include
# what it uses: the header check (tests/header_check) compiles each public
# header alone, without these. -DCMAKE_DISABLE_PRECOMPILE_HEADERS=ON builds any
# tree without them (CMake's own switch), to check a source file's includes.
set(GMR_PCH_CORE
  <algorithm> <array> <cmath> <cstdint> <functional> <map> <memory> <optional>
  <span> <string> <string_view> <utility> <vector>
  <Eigen/Core> <Eigen/Geometry>)
# boost/asio/awaitable.hpp uses std::exchange without including <utility>,
# which the core list brings first.
set(GMR_PCH_ASIO <boost/asio.hpp>)
set(GMR_PCH_LOG <spdlog/spdlog.h>)  # only in targets that link spdlog::spdlog (its macros)
set(GMR_PCH_PROTO
  <google/protobuf/generated_message_reflection.h> <google/protobuf/message.h>
  <google/protobuf/repeated_field.h>)
set(GMR_PCH_TEST <gtest/gtest.h>)

# gmr_precompile(target CORE|ASIO|LOG|PROTO|TEST...): the lists named, added
# to what the target has. A target of one or two files gains nothing (the
# header is compiled once per target), so the callers leave those out.
function(gmr_precompile target)
  set(headers "")
  foreach(kind IN LISTS ARGN)
    list(APPEND headers ${GMR_PCH_${kind}})
  endforeach()
  target_precompile_headers(${target} PRIVATE ${headers})
endfunction()
