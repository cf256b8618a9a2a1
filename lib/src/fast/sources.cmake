# Sources of the fast area: the compiled float motion, the SIMD FK kernels
# (Highway: one copy per x86 target, picked at run time, so no -march flag is
# needed) and the .gmrb binary format.
find_package(hwy REQUIRED)
target_sources(gmr PRIVATE
  src/fast/compiled_motion.cpp
  src/fast/fast_fk.cpp
  src/fast/fk_kernels.cpp
  src/fast/gmrb.cpp
)
# fk_kernels.cpp re-includes itself through Highway's foreach_target.h by the
# path "src/fast/fk_kernels.cpp", relative to lib/.
target_include_directories(gmr PRIVATE ${CMAKE_CURRENT_SOURCE_DIR})
target_link_libraries(gmr PRIVATE hwy::hwy)
