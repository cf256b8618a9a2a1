# Sources of the markers area: C3D and TRC marker readers, the TRC writer,
# loading by extension.
target_sources(gmr PRIVATE
  src/markers/c3d.cpp
  src/markers/trc.cpp
  src/markers/markers.cpp
)
