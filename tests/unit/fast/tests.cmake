# Generated motions, job validity and the .gmrb reader: also run under ASan/UBSan.
gmr_add_test(gmr_fast_tests SANITIZE
  unit/fast/fast_fk_test.cpp
  unit/fast/gmrb_test.cpp
)
# Every BVH of the corpus, every frame, in several root configurations (Release only: long under ASan).
gmr_add_test(gmr_fast_data_tests
  unit/fast/fast_fk_data_test.cpp
)
# Jobs are filled with designated initializers that leave optional fields at their defaults.
target_compile_options(gmr_fast_tests PRIVATE -Wno-missing-field-initializers)
target_compile_options(gmr_fast_data_tests PRIVATE -Wno-missing-field-initializers)
