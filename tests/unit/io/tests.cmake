# IO area: BVH and GMR text readers/writers, file helpers, load/save by
# extension, positions CSV, and a deterministic mutation test of the readers.
gmr_add_test(gmr_io_tests SANITIZE
  unit/io/bvh_test.cpp
  unit/io/gmr_file_test.cpp
  unit/io/file_util_test.cpp
  unit/io/positions_csv_test.cpp
  unit/io/motion_file_test.cpp
  unit/io/mutation_test.cpp
)
