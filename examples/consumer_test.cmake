# Installs a planeslam build tree into a prefix under it, builds examples/detect_planes,
# examples/odometry and examples/slam against that prefix as separate CMake projects, and runs
# them on the shared data. Run by ctest (tests/CMakeLists.txt) as
#   cmake -DBUILD_DIR=... -DSOURCE_DIR=... -DDATA_DIR=... -DCXX_COMPILER=... [...] -P this file
# The examples are built with the build tree's compiler, flags and build type; in a sanitizer
# build the installed libraries carry -fsanitize in their link interface, so the examples link
# the same runtime. Prints "consumer test skipped" (ctest: skipped) when the data is absent.
cmake_minimum_required(VERSION 3.22)

foreach(_var BUILD_DIR SOURCE_DIR DATA_DIR CXX_COMPILER)
  if(NOT ${_var})
    message(FATAL_ERROR "consumer_test.cmake: -D${_var}=... is required")
  endif()
endforeach()
if(DEFINED ENV{PLANESLAM_DATA_DIR} AND NOT "$ENV{PLANESLAM_DATA_DIR}" STREQUAL "")
  set(DATA_DIR "$ENV{PLANESLAM_DATA_DIR}")
endif()

function(run_checked what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE _rc OUTPUT_VARIABLE _out ERROR_VARIABLE _err)
  if(NOT _rc EQUAL 0)
    message(FATAL_ERROR "${what} failed (${_rc}):\n${_out}\n${_err}")
  endif()
  set(LAST_OUTPUT "${_out}" PARENT_SCOPE)
endfunction()

set(_work ${BUILD_DIR}/test_tmp/consumer)
set(_prefix ${_work}/prefix)
file(REMOVE_RECURSE ${_prefix})
run_checked("cmake --install" ${CMAKE_COMMAND} --install ${BUILD_DIR} --prefix ${_prefix})

set(_args -DCMAKE_PREFIX_PATH=${_prefix} -DCMAKE_CXX_COMPILER=${CXX_COMPILER}
          -DCMAKE_BUILD_TYPE=${BUILD_TYPE} "-DCMAKE_CXX_FLAGS=${CXX_FLAGS}")
if(COMPILER_LAUNCHER)
  list(APPEND _args -DCMAKE_CXX_COMPILER_LAUNCHER=${COMPILER_LAUNCHER})
endif()
foreach(_example detect_planes odometry slam)
  file(REMOVE_RECURSE ${_work}/${_example})
  run_checked("configuring examples/${_example}" ${CMAKE_COMMAND} -S ${SOURCE_DIR}/examples/${_example}
              -B ${_work}/${_example} ${_args})
  run_checked("building examples/${_example}" ${CMAKE_COMMAND} --build ${_work}/${_example})
endforeach()

set(_frame ${DATA_DIR}/depth_frames/tum_fr3_long_office_1341848230.910894.png)
set(_sequence ${DATA_DIR}/tum_fr3_structure_notexture_far)
if(NOT EXISTS ${_frame} OR NOT EXISTS ${_sequence}/depth.txt)
  message("consumer test skipped: the examples built, but ${DATA_DIR} lacks ${_frame} or "
          "${_sequence}/depth.txt (set PLANESLAM_DATA_DIR)")
  return()
endif()

run_checked("detect_planes" ${_work}/detect_planes/detect_planes ${_frame} 535.4 539.2 320.1 247.6)
message("${LAST_OUTPUT}")
if(NOT LAST_OUTPUT MATCHES "^grid3: [1-9][0-9]* planes in 640x480\nplane 1: n = ")
  message(FATAL_ERROR "detect_planes: unexpected output")
endif()

run_checked("odometry" ${_work}/odometry/odometry ${_sequence} 30)
message("${LAST_OUTPUT}")
if(NOT LAST_OUTPUT MATCHES "\n# 30 frames, path length 0\\.[0-9]+ m\n$")
  message(FATAL_ERROR "odometry: unexpected output")
endif()

run_checked("slam" ${_work}/slam/slam ${_sequence} ${_work}/slam_out 30)
message("${LAST_OUTPUT}")
if(NOT LAST_OUTPUT MATCHES "^# 30 frames, [1-9][0-9]* keyframes, [1-9][0-9]* map planes, final cost "
   OR NOT EXISTS ${_work}/slam_out/trajectory_tum.txt OR NOT EXISTS ${_work}/slam_out/plane_map.ply)
  message(FATAL_ERROR "slam: unexpected output")
endif()
