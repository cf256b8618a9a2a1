# Markers area: C3D and TRC readers on every real file, the TRC writer's round
# trips, the CMU 02_01 cross-check against its BVH, malformed files, and a
# seeded mutation test of both readers (runs under ASan/UBSan).
gmr_add_test(gmr_markers_tests SANITIZE
  unit/markers/c3d_test.cpp
  unit/markers/trc_test.cpp
  unit/markers/markers_mutation_test.cpp
  unit/markers/markers_test_util.h
)
target_include_directories(gmr_markers_tests PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/unit/io)
