# Third-party dependencies, all from Debian 12 packages (see Makefile 'deps').
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(yaml-cpp REQUIRED)
find_package(CLI11 REQUIRED)
find_package(nlohmann_json 3 REQUIRED)
find_package(PNG REQUIRED)
find_package(ZLIB REQUIRED)
find_package(Ceres REQUIRED)
find_package(Threads REQUIRED)
find_package(absl REQUIRED)

if(PLANESLAM_WITH_OCTOMAP)
  find_package(octomap REQUIRED)
  add_library(planeslam_octomap INTERFACE IMPORTED GLOBAL)
  target_include_directories(planeslam_octomap SYSTEM INTERFACE ${OCTOMAP_INCLUDE_DIRS})
  target_link_libraries(planeslam_octomap INTERFACE ${OCTOMAP_LIBRARIES})
  target_compile_definitions(planeslam_octomap INTERFACE PLANESLAM_HAVE_OCTOMAP=1)
endif()

if(PLANESLAM_WITH_PCL)
  # Debian's VTK (dragged in by PCL's config) needs MPI's C target to exist first, else CMake stops
  # with "The link interface of target VTK::mpi contains MPI::MPI_C".
  find_package(MPI COMPONENTS C)
  find_package(PCL 1.10 REQUIRED COMPONENTS common io features segmentation filters registration
                                            search kdtree)
  # Wrap PCL once so only the targets that need it see its include paths and flags.
  add_library(planeslam_pcl INTERFACE IMPORTED GLOBAL)
  target_include_directories(planeslam_pcl SYSTEM INTERFACE ${PCL_INCLUDE_DIRS})
  target_link_libraries(planeslam_pcl INTERFACE ${PCL_LIBRARIES})
  target_compile_definitions(planeslam_pcl INTERFACE PLANESLAM_HAVE_PCL=1)
endif()
