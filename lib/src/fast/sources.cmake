# Sources of the fast area: target_sources(gmr PRIVATE src/fast/...)
