# Sources of the ops area: target_sources(gmr PRIVATE src/ops/...)
