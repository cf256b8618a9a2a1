# Acclaim ASF/AMC: readers, writers, the Acclaim model's FK and the GMR conversions.
target_sources(gmr PRIVATE
  src/asf/asf_reader.cpp
  src/asf/amc_reader.cpp
  src/asf/acclaim_kinematics.cpp
  src/asf/asf_amc.cpp
)
