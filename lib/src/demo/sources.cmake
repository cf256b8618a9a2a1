target_sources(gmr PRIVATE src/demo/demo_library.cpp)
