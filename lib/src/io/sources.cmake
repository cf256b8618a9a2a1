# Sources of the io area: target_sources(gmr PRIVATE src/io/...)
