# The installed CMake package: `cmake --install build --prefix P` puts the module libraries,
# their headers and lib/cmake/planeslam/planeslam{Config,ConfigVersion,Targets}.cmake under P, so
# that find_package(planeslam CONFIG REQUIRED) gives planeslam::core, io, eval, sim, detection,
# registration and mapping. The executable, its app layer and the PCL baselines stay out.
include(CMakePackageConfigHelpers)

set(PLANESLAM_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/planeslam)

install(EXPORT planeslamTargets NAMESPACE planeslam:: FILE planeslamTargets.cmake
        DESTINATION ${PLANESLAM_INSTALL_CMAKEDIR})

configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/planeslamConfig.cmake.in
                              ${CMAKE_CURRENT_BINARY_DIR}/planeslamConfig.cmake
                              INSTALL_DESTINATION ${PLANESLAM_INSTALL_CMAKEDIR})
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/planeslamConfigVersion.cmake
                                 COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/planeslamConfig.cmake
              ${CMAKE_CURRENT_BINARY_DIR}/planeslamConfigVersion.cmake
        DESTINATION ${PLANESLAM_INSTALL_CMAKEDIR})
