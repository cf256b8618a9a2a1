# ctest script (cmake -P): installs gmr::gmr from the build tree into a fresh
# prefix under WORK_DIR, then configures, builds and runs the consumer project
# (consumer/) against that prefix with the same compiler and generator, and
# checks what it prints. Writes only under WORK_DIR (in the build tree).
#
# -D variables: GMR_BINARY_DIR, CONSUMER_DIR, WORK_DIR, GENERATOR,
# MAKE_PROGRAM, CXX_COMPILER, BUILD_TYPE, INSTALL_LIBDIR, GMR_VERSION, and
# optionally CXX_FLAGS / LINKER_FLAGS (sanitizer builds: the consumer links an
# instrumented archive). With CLIENT=ON (and C_COMPILER): everything is
# installed, and the consumer also uses the installed C++ client and C ABI
# against the installed gmr-server, started here on loopback.
foreach(var GMR_BINARY_DIR CONSUMER_DIR WORK_DIR GENERATOR CXX_COMPILER INSTALL_LIBDIR GMR_VERSION)
  if(NOT DEFINED ${var} OR "${${var}}" STREQUAL "")
    message(FATAL_ERROR "package_test.cmake: -D${var}=... is required")
  endif()
endforeach()

# run(<what> COMMAND...): runs the command, fails the test with its output if it fails.
function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${rc}):\n${ARGN}\n${out}\n${err}")
  endif()
  set(run_output "${out}" PARENT_SCOPE)
endfunction()

set(prefix ${WORK_DIR}/prefix)
if(NOT CLIENT)
  set(CLIENT OFF)
endif()
set(c_compiler "")
if(C_COMPILER)
  set(c_compiler -DCMAKE_C_COMPILER=${C_COMPILER})
endif()
set(build ${WORK_DIR}/consumer-build)
file(REMOVE_RECURSE ${WORK_DIR})
file(MAKE_DIRECTORY ${WORK_DIR})

set(expected ${INSTALL_LIBDIR}/cmake/gmr/gmrConfig.cmake ${INSTALL_LIBDIR}/cmake/gmr/gmrConfigVersion.cmake
             ${INSTALL_LIBDIR}/cmake/gmr/gmrTargets.cmake ${INSTALL_LIBDIR}/libgmr.a
             include/gmr/core/error.h include/gmr/fast/fast_fk.h)
if(CLIENT)
  run("install" ${CMAKE_COMMAND} --install ${GMR_BINARY_DIR} --prefix ${prefix})
  list(APPEND expected ${INSTALL_LIBDIR}/libgmr_client.a ${INSTALL_LIBDIR}/libgmr_wire.a ${INSTALL_LIBDIR}/libgmr_proto.a
       ${INSTALL_LIBDIR}/libgmr_client_c.so.0 ${INSTALL_LIBDIR}/pkgconfig/gmr_client_c.pc
       ${INSTALL_LIBDIR}/cmake/gmr/gmrClientTargets.cmake ${INSTALL_LIBDIR}/cmake/gmr/gmrClientCTargets.cmake
       include/gmr/client/client.h include/gmr/wire/frame_values.h include/gmr_client_c.h
       bin/gmr bin/gmr-server bin/gmr-load
       ${INSTALL_LIBDIR}/python3/dist-packages/gmr_client/stream_pb2.py
       ${INSTALL_LIBDIR}/python3/dist-packages/gmr_client/client.py
       share/gmr/blender/gmr_live_link/__init__.py share/gmr/blender/gmr_live_link/link.py
       share/gmr/web/index.html share/gmr/web/viewer.js share/gmr/web/viewer.css)
else()
  run("install" ${CMAKE_COMMAND} --install ${GMR_BINARY_DIR} --prefix ${prefix} --component gmr)
endif()
foreach(file ${expected})
  if(NOT EXISTS ${prefix}/${file})
    message(FATAL_ERROR "install: ${prefix}/${file} is missing")
  endif()
endforeach()
# Nothing private (lib/src) or from other targets gets installed; of the
# client side only its headers without protobuf types.
file(GLOB_RECURSE installed_headers RELATIVE ${prefix}/include ${prefix}/include/*)
foreach(header ${installed_headers})
  if(header STREQUAL "gmr/client/client.h" OR header STREQUAL "gmr/wire/frame_values.h"
     OR header STREQUAL "gmr_client_c.h")
    continue()
  endif()
  if(NOT header MATCHES "^gmr/[a-z0-9_]+/[a-z0-9_]+\\.h$" OR header MATCHES "^gmr/(wire|server|client|stream)/")
    message(FATAL_ERROR "install: unexpected file include/${header}")
  endif()
endforeach()

# CMAKE_FIND_USE_PACKAGE_REGISTRY=OFF: only the fresh prefix can provide gmr.
run("consumer configure" ${CMAKE_COMMAND} -S ${CONSUMER_DIR} -B ${build} -G ${GENERATOR}
    -DCMAKE_MAKE_PROGRAM=${MAKE_PROGRAM} -DCMAKE_CXX_COMPILER=${CXX_COMPILER} -DCMAKE_BUILD_TYPE=${BUILD_TYPE}
    -DCMAKE_PREFIX_PATH=${prefix} -DCMAKE_FIND_USE_PACKAGE_REGISTRY=OFF
    -DGMR_CONSUMER_CLIENT=${CLIENT} ${c_compiler}
    "-DCMAKE_CXX_FLAGS=${CXX_FLAGS}" "-DCMAKE_C_FLAGS=${CXX_FLAGS}" "-DCMAKE_EXE_LINKER_FLAGS=${LINKER_FLAGS}")
string(REGEX MATCH "consumer: gmr ([0-9.]+) from ([^\n]*)" found "${run_output}")
if(NOT CMAKE_MATCH_1 STREQUAL GMR_VERSION OR NOT CMAKE_MATCH_2 STREQUAL "${prefix}/${INSTALL_LIBDIR}/cmake/gmr")
  message(FATAL_ERROR "consumer configure: expected gmr ${GMR_VERSION} from ${prefix}/${INSTALL_LIBDIR}/cmake/gmr, "
                      "got '${found}'\n${run_output}")
endif()

set(config_args)
if(BUILD_TYPE)
  set(config_args --config ${BUILD_TYPE})
endif()
run("consumer build" ${CMAKE_COMMAND} --build ${build} ${config_args})
run("consumer run" ${build}/gmr_consumer)
message("${run_output}")
if(NOT run_output MATCHES "^gmr consumer: [a-z]+, [0-9]+ joints, [0-9]+ frames, frame [0-9]+, SIMD [A-Za-z0-9_]+\n"
   OR NOT run_output MATCHES "\nfast FK matches the reference")
  message(FATAL_ERROR "consumer run: unexpected output")
endif()

if(CLIENT)
  # The README's pkg-config line, as a user types it: a plain compiler call,
  # no CMake, no LD_LIBRARY_PATH. Before, its program did not start from a
  # non-system prefix (libgmr_client_c.so.0 not found); the .pc file now
  # carries an rpath.
  run("the README's pkg-config line" sh -c
      "${C_COMPILER} ${CXX_FLAGS} '${CONSUMER_DIR}/c_main.c' -o '${WORK_DIR}/readme_c_consumer' $(PKG_CONFIG_PATH='${prefix}/${INSTALL_LIBDIR}/pkgconfig' pkg-config --cflags --libs gmr_client_c)")
  # The installed server on a free loopback port, the installed gmr command
  # and the four client consumers against it.
  # No semicolons: CMake would split the script at them. The server writes to
  # a file, so it never holds execute_process's pipe.
  set(script "
    '${prefix}/bin/gmr-server' --port 0 --port-file '${WORK_DIR}/port' >'${WORK_DIR}/server.log' 2>&1 &
    pid=$!
    for i in $(seq 200)
    do
      [ -s '${WORK_DIR}/port' ] && break
      sleep 0.05
    done
    port=$(cat '${WORK_DIR}/port')
    '${prefix}/bin/gmr' ls --port $port >/dev/null && '${build}/gmr_client_consumer' $port &&
      '${build}/gmr_c_consumer' $port && '${build}/gmr_c_pkgconfig_consumer' $port &&
      env -u LD_LIBRARY_PATH '${WORK_DIR}/readme_c_consumer' $port
    rc=$?
    kill -TERM $pid
    wait $pid || rc=1
    exit $rc")
  run("installed server and clients" sh -c "${script}")
  if(PYTHON)  # the installed Python client, from the prefix alone
    execute_process(COMMAND ${PYTHON} -c "import google.protobuf, numpy" RESULT_VARIABLE have_modules
                    OUTPUT_QUIET ERROR_QUIET)
    if(NOT have_modules EQUAL 0)
      if("$ENV{CI}" STREQUAL "true")
        message(FATAL_ERROR "${PYTHON} cannot import google.protobuf and numpy (CI=true)")
      endif()
      message("skipped: the installed Python client (no python3-protobuf or numpy for ${PYTHON})")
      set(PYTHON "")
    endif()
  endif()
  if(PYTHON)
    execute_process(COMMAND ${CMAKE_COMMAND} -E env PYTHONPATH=${prefix}/${INSTALL_LIBDIR}/python3/dist-packages
                            ${PYTHON} -c "import gmr_client, gmr_client.stream_pb2; print('python client', gmr_client.PROTOCOL_VERSION)"
                    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
    if(NOT rc EQUAL 0 OR NOT out MATCHES "python client 1")
      message(FATAL_ERROR "the installed Python client does not import (${rc}): ${out}${err}")
    endif()
  endif()
  message("${run_output}")
  # The installed server serves the installed viewer, not the source tree's.
  file(READ ${WORK_DIR}/server.log server_log)
  if(NOT server_log MATCHES "viewer: http://127.0.0.1:[0-9]+/ .*files from ${prefix}/share/gmr/web")
    message(FATAL_ERROR "the installed gmr-server does not serve ${prefix}/share/gmr/web:\n${server_log}")
  endif()
  foreach(line "client consumer: [0-9]+ motions, 10 frames" "c consumer: frame [0-9]+ of")
    if(NOT run_output MATCHES "${line}")
      message(FATAL_ERROR "clients against the installed server: no '${line}' in\n${run_output}")
    endif()
  endforeach()
endif()
file(REMOVE_RECURSE ${WORK_DIR})
