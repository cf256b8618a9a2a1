gmr_add_test(gmr_core_tests SANITIZE
  unit/core/rotation_test.cpp
  unit/core/skeleton_test.cpp
  unit/core/forward_kinematics_test.cpp
  unit/core/demo_library_test.cpp
)
