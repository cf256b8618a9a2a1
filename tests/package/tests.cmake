# The install and the CMake package: gmr::gmr installed into a fresh prefix
# and used from a separate project (package_test.cmake). Only when gmr
# itself is built here with GMR_INSTALL (not when tests/ is built against an
# installed gmr).
if(GMR_INSTALL AND TARGET gmr)
  include(GNUInstallDirs)
  set(consumer_flags "")
  if(GMR_SANITIZE)  # the installed archive is instrumented: the consumer must link the runtimes
    set(consumer_flags "-fsanitize=address,undefined")
  endif()
  add_test(NAME gmr_package_test
           COMMAND ${CMAKE_COMMAND}
                   -DGMR_BINARY_DIR=${PROJECT_BINARY_DIR}
                   -DCONSUMER_DIR=${CMAKE_CURRENT_LIST_DIR}/consumer
                   -DWORK_DIR=${CMAKE_CURRENT_BINARY_DIR}/package_test
                   -DGENERATOR=${CMAKE_GENERATOR}
                   -DMAKE_PROGRAM=${CMAKE_MAKE_PROGRAM}
                   -DCXX_COMPILER=${CMAKE_CXX_COMPILER}
                   -DBUILD_TYPE=$<CONFIG>
                   -DINSTALL_LIBDIR=${CMAKE_INSTALL_LIBDIR}
                   -DGMR_VERSION=${PROJECT_VERSION}
                   -DCXX_FLAGS=${consumer_flags}
                   -DLINKER_FLAGS=${consumer_flags}
                   -P ${CMAKE_CURRENT_LIST_DIR}/package_test.cmake)
  set_tests_properties(gmr_package_test PROPERTIES LABELS unit TIMEOUT 300)
endif()
