# Install the library so other projects can find_package(meshsweeper CONFIG).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)
# A sanitized static library needs the sanitizer runtime in every program that links it.
if(MESHSWEEPER_SANITIZE)
  target_link_options(meshsweeper INTERFACE -fsanitize=${MESHSWEEPER_SANITIZE})
endif()
install(TARGETS meshsweeper EXPORT meshsweeperTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
# The OpenVDB cross-check (collision/vdb_check.h, library meshsweeper_vdb) serves the tests and
# `meshsweep check`; it is not installed, nor its header.
foreach(module core deform collision)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${module}/ DESTINATION include/meshsweeper/${module}
          FILES_MATCHING PATTERN "*.h" PATTERN "vdb_check.h" EXCLUDE)
endforeach()
install(EXPORT meshsweeperTargets NAMESPACE meshsweeper::
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/meshsweeper)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/meshsweeperConfig.cmake.in
  ${PROJECT_BINARY_DIR}/meshsweeperConfig.cmake
  INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/meshsweeper)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/meshsweeperConfigVersion.cmake
  COMPATIBILITY SameMajorVersion)
install(FILES ${PROJECT_BINARY_DIR}/meshsweeperConfig.cmake
              ${PROJECT_BINARY_DIR}/meshsweeperConfigVersion.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/meshsweeper)
