# OPS area: conversions (post <-> pre rotation), GMR operations, views.
# gmr_ops_tests: fast synthetic tests (also run under ASan/UBSan).
# gmr_ops_data_tests: every BVH of ../shared/data, every frame (Release only).
gmr_add_test(gmr_ops_tests SANITIZE
  unit/ops/convert_test.cpp
  unit/ops/ops_test.cpp
  unit/ops/view_test.cpp
)
gmr_add_test(gmr_ops_data_tests
  unit/ops/ops_data_test.cpp
)
