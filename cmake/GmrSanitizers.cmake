# Debug information in the sanitizer and fuzzing trees: line tables only
# (clang's -gline-tables-only), enough for the reports' symbolized stack
# traces and much cheaper to compile and link than full -g (those trees are
# built in every CI run). Configure a tree of your own with -g to debug in gdb.
if(GMR_SANITIZE OR GMR_FUZZ OR GMR_TSAN)
  if(CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    set(GMR_SANITIZER_DEBUG_INFO -gline-tables-only)
    foreach(config DEBUG RELWITHDEBINFO)
      string(REGEX REPLACE "(^| )-g( |$)" "\\1-gline-tables-only\\2" CMAKE_CXX_FLAGS_${config}
                           "${CMAKE_CXX_FLAGS_${config}}")
    endforeach()
  else()
    set(GMR_SANITIZER_DEBUG_INFO -g)
  endif()
endif()
# GMR_SANITIZE=ON builds everything with ASan and UBSan; any report aborts the
# process so a test that trips one fails. GMR_SANITIZED tells the code (the
# same with GCC and clang, which spell their own macros differently).
if(GMR_SANITIZE OR GMR_FUZZ)
  add_compile_options(-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer
                      ${GMR_SANITIZER_DEBUG_INFO})
  add_link_options(-fsanitize=address,undefined)
  add_compile_definitions(GMR_SANITIZED=1)
endif()
# GMR_TSAN=ON: ThreadSanitizer instead (it cannot be combined with ASan); a
# reported race fails the test (halt_on_error in the tests' environment).
if(GMR_TSAN)
  if(GMR_SANITIZE OR GMR_FUZZ)
    message(FATAL_ERROR "GMR_TSAN cannot be combined with GMR_SANITIZE or GMR_FUZZ")
  endif()
  add_compile_options(-fsanitize=thread -fno-omit-frame-pointer ${GMR_SANITIZER_DEBUG_INFO})
  add_link_options(-fsanitize=thread)
  add_compile_definitions(GMR_SANITIZED=1 GMR_TSAN=1)
endif()
# GMR_FUZZ: every object is instrumented for libFuzzer's coverage; the
# harnesses (fuzz/) link its main.
if(GMR_FUZZ)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR "GMR_FUZZ needs clang (libFuzzer): -DCMAKE_CXX_COMPILER=clang++")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link)
endif()
# GMR_FUZZ_HARNESSES: the harnesses in a GMR_SANITIZE tree, which instruments
# for coverage only the code they fuzz (fuzz/coverage-allowlist.txt): the
# tree's tests keep ASan's speed (coverage everywhere made them half again as
# slow) and its Highway kernels keep every target, and CI builds the library
# and the server under ASan once, not twice (make fuzz-smoke).
if(GMR_FUZZ_HARNESSES)
  if(NOT GMR_SANITIZE OR NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
    message(FATAL_ERROR "GMR_FUZZ_HARNESSES needs GMR_SANITIZE=ON and clang (libFuzzer)")
  endif()
  if(GMR_FUZZ)
    message(FATAL_ERROR "GMR_FUZZ_HARNESSES is GMR_FUZZ with less coverage: use one of them")
  endif()
  add_compile_options(-fsanitize=fuzzer-no-link
                      -fsanitize-coverage-allowlist=${PROJECT_SOURCE_DIR}/fuzz/coverage-allowlist.txt)
endif()
