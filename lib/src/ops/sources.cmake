# Sources of the ops area: conversions (post <-> pre rotation), the GMR
# operations (shift, split, join, set roots, dummies) and views.
target_sources(gmr PRIVATE
  src/ops/work.cpp
  src/ops/convert.cpp
  src/ops/ops.cpp
  src/ops/view.cpp
)
