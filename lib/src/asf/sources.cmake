target_sources(gmr PRIVATE src/asf/asf_amc.cpp)
