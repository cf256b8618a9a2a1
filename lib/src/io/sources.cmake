# Sources of the io area: BVH and GMR text readers/writers, file helpers,
# load/save by extension, the positions CSV.
target_sources(gmr PRIVATE
  src/io/file_util.cpp
  src/io/hierarchy_text.cpp
  src/io/bvh.cpp
  src/io/gmr_file.cpp
  src/io/positions_csv.cpp
  src/io/motion_file.cpp
  src/io/motion_save.cpp
)
