# What `cmake --install` puts beside gmr::gmr (which lib/ installs): the C++
# client (gmr::client, with the gmr::wire and gmr::proto archives it needs;
# its headers have no protobuf types), the C ABI (libgmr_client_c.so, its
# header, a pkg-config file and gmr::client_c), the programs, the Python
# client (lib/python3/dist-packages/gmr_client, its protocol module
# generated), the Blender add-on (share/gmr/blender/gmr_live_link) and the
# browser viewer's files (share/gmr/web).
# Components: gmr, client, client_c, programs, python. find_package(gmr COMPONENTS client
# client_c) loads the client targets (cmake/gmrConfig.cmake.in).
include(GNUInstallDirs)
set(GMR_CONFIG_INSTALL_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/gmr)

if(TARGET gmr_client)
  target_include_directories(gmr_client PUBLIC $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  set_target_properties(gmr_proto PROPERTIES EXPORT_NAME proto)
  set_target_properties(gmr_wire PROPERTIES EXPORT_NAME wire)
  set_target_properties(gmr_client PROPERTIES EXPORT_NAME client)
  install(TARGETS gmr_proto gmr_wire gmr_client EXPORT gmrClientTargets
          ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT client)
  install(FILES ${PROJECT_SOURCE_DIR}/client/include/gmr/client/client.h
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/gmr/client COMPONENT client)
  install(FILES ${PROJECT_SOURCE_DIR}/proto/wire/include/gmr/wire/frame_values.h
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/gmr/wire COMPONENT client)
  install(EXPORT gmrClientTargets NAMESPACE gmr:: DESTINATION ${GMR_CONFIG_INSTALL_DIR} COMPONENT client)
endif()

if(TARGET gmr_client_c)
  set_target_properties(gmr_client_c PROPERTIES EXPORT_NAME client_c)
  install(TARGETS gmr_client_c EXPORT gmrClientCTargets
          LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT client_c NAMELINK_COMPONENT client_c)
  install(FILES ${PROJECT_SOURCE_DIR}/client/c/include/gmr_client_c.h
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR} COMPONENT client_c)
  install(EXPORT gmrClientCTargets NAMESPACE gmr:: DESTINATION ${GMR_CONFIG_INSTALL_DIR} COMPONENT client_c)
  # Relocatable: the prefix is found from where the .pc file is (an install
  # with --prefix, or a copied tree, still works).
  file(RELATIVE_PATH pc_to_prefix /prefix/${CMAKE_INSTALL_LIBDIR}/pkgconfig /prefix)
  set(GMR_PC_PREFIX "\${pcfiledir}/${pc_to_prefix}")
  configure_file(${PROJECT_SOURCE_DIR}/client/c/gmr_client_c.pc.in ${PROJECT_BINARY_DIR}/gmr_client_c.pc @ONLY)
  install(FILES ${PROJECT_BINARY_DIR}/gmr_client_c.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig
          COMPONENT client_c)
endif()

if(TARGET gmr_python_client)
  install(DIRECTORY ${GMR_PYTHON_DIR}/gmr_client DESTINATION ${CMAKE_INSTALL_LIBDIR}/python3/dist-packages
          COMPONENT python FILES_MATCHING PATTERN "*.py")
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/client/blender/gmr_live_link DESTINATION ${CMAKE_INSTALL_DATADIR}/gmr/blender
          COMPONENT python FILES_MATCHING PATTERN "*.py")
endif()

foreach(program gmr_cli gmr_server_bin gmr_load)
  if(TARGET ${program})
    install(TARGETS ${program} RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT programs)
  endif()
endforeach()
# The browser viewer's files, which the installed gmr-server finds beside it
# (BINDIR/../share/gmr/web); three.js comes from Debian's libjs-three.
if(TARGET gmr_server_bin)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/server/web/ DESTINATION ${CMAKE_INSTALL_DATADIR}/gmr/web COMPONENT programs)
endif()
