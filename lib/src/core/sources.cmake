target_sources(gmr PRIVATE
  src/core/error.cpp
  src/core/rotation.cpp
  src/core/skeleton.cpp
  src/core/motion.cpp
  src/core/forward_kinematics.cpp
)
