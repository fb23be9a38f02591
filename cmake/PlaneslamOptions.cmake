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

include(GNUInstallDirs)

# planeslam_add_module(<name> DEPS <public deps...> PRIVATE_DEPS <...>)
# One static library per module: sources are every .cpp in <name>/src (globbed so new files
# join the build on the next configure), public headers in <name>/include/planeslam/<name>.
# The target is planeslam_<name>, aliased and exported as planeslam::<name>; its library and
# headers join the install set planeslamTargets (cmake/PlaneslamInstall.cmake writes the package).
function(planeslam_add_module name)
  cmake_parse_arguments(ARG "" "" "DEPS;PRIVATE_DEPS" ${ARGN})
  file(GLOB _src CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/src/*.cpp)
  set(_target planeslam_${name})
  set(_include $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
               $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  if(NOT _src)
    # A module with headers only so far.
    add_library(${_target} INTERFACE)
    target_include_directories(${_target} INTERFACE ${_include})
    target_link_libraries(${_target} INTERFACE ${ARG_DEPS})
  else()
    add_library(${_target} STATIC ${_src})
    target_include_directories(${_target} PUBLIC ${_include}
                                          PRIVATE ${CMAKE_CURRENT_SOURCE_DIR}/src)
    # A static library's private dependencies are exported as link-only ones.
    target_link_libraries(${_target} PUBLIC ${ARG_DEPS} PRIVATE ${ARG_PRIVATE_DEPS})
    planeslam_set_options(${_target})
    if(PLANESLAM_SANITIZERS)
      # Objects built with sanitizers need their runtime wherever they are linked.
      string(REPLACE ";" "," _san "${PLANESLAM_SANITIZERS}")
      target_link_options(${_target} INTERFACE $<INSTALL_INTERFACE:-fsanitize=${_san}>)
    endif()
  endif()
  add_library(planeslam::${name} ALIAS ${_target})
  set_target_properties(${_target} PROPERTIES EXPORT_NAME ${name})
  install(TARGETS ${_target} EXPORT planeslamTargets
          ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR})
  install(DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
endfunction()
