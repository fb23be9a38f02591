# Compiler warnings and sanitizers, applied per target through planeslam_set_options().
function(planeslam_set_options target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic)
  if(PLANESLAM_SANITIZERS)
    string(REPLACE ";" "," _san "${PLANESLAM_SANITIZERS}")
    target_compile_options(${target} PRIVATE -fsanitize=${_san} -fno-omit-frame-pointer
                                             -fno-sanitize-recover=all)
    target_link_options(${target} PRIVATE -fsanitize=${_san})
  endif()
endfunction()

# planeslam_add_module(<name> DEPS <public deps...> PRIVATE_DEPS <...>)
# One static library per module: sources are every .cpp in <name>/src (globbed so new files
# join the build on the next configure), public headers in <name>/include/planeslam/<name>.
function(planeslam_add_module name)
  cmake_parse_arguments(ARG "" "" "DEPS;PRIVATE_DEPS" ${ARGN})
  file(GLOB _src CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/src/*.cpp)
  if(NOT _src)
    # A module with headers only so far.
    add_library(planeslam_${name} INTERFACE)
    add_library(planeslam::${name} ALIAS planeslam_${name})
    target_include_directories(planeslam_${name} INTERFACE ${CMAKE_CURRENT_SOURCE_DIR}/include)
    target_link_libraries(planeslam_${name} INTERFACE ${ARG_DEPS})
    return()
  endif()
  add_library(planeslam_${name} STATIC ${_src})
  add_library(planeslam::${name} ALIAS planeslam_${name})
  target_include_directories(planeslam_${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include
                                               PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src)
  target_link_libraries(planeslam_${name} PUBLIC ${ARG_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
  planeslam_set_options(planeslam_${name})
endfunction()
