# Acclaim ASF/AMC: readers (every ASF/AMC pitfall), writers, the Acclaim model's
# FK, the GMR conversions, and the cross-check against the BVH of CMU 01_01.
gmr_add_test(gmr_asf_tests SANITIZE
  unit/asf/asf_reader_test.cpp
  unit/asf/amc_reader_test.cpp
  unit/asf/acclaim_convert_test.cpp
  unit/asf/asf_writer_test.cpp
  unit/asf/cmu_bvh_test.cpp
)
