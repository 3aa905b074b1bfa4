# add_fmu(NAME <ModelIdentifier>
#         [FMI <2|3 ...>]               # the standards to build the model's FMU for (default: 2);
#                                       # FMI 3: the FMI 3.0 FMU, below
#         SOURCES <.cpp ...>            # the one that includes fmi2_entry_points.inc (or
#                                       # fmi3_entry_points.inc), plus model sources; @FMI@ in a
#                                       # name stands for the standard (fmi@FMI@_plant.cpp)
#         [LIBRARIES <targets ...>]     # linked into the FMU and its generator
#         [RESOURCES <files ...>]       # copied into resources/ (files, not directories)
#         [DOCUMENTATION <index.html>]) # copied to documentation/index.html, with the variable
#                                       # reference generated from the variable table put at
#                                       # its <!-- ipmsm-fmu:variables --> marker (required)
#
# Builds an FMI 2.0 co-simulation FMU for Linux x86-64 (and for Windows x86-64, see below):
#   <NAME>                    the shared library <NAME>.so: hidden visibility, only the fmi2* functions
#                             exported (fmu_src/fmi/exports.map), no undefined symbols, unused
#                             sections dropped; libstdc++ linked statically, libgcc_s dynamically
#                             (a static libgcc's unwinder needs glibc 2.35's _dl_find_object), and
#                             the newer glibc symbol versions redirected to old ones
#                             (fmu_src/fmi/glibc_compat.cpp): it needs libc, libm and libgcc_s of
#                             glibc 2.17 or later (tests/python/test_conformance.py)
#   <NAME>_modelDescription   the generator: the same SOURCES compiled with IPMSM_FMI2_GENERATOR
#   <NAME>_fmu (ALL)          runs the generator and assembles ${CMAKE_BINARY_DIR}/fmu/<NAME>/
#                             (modelDescription.xml, binaries/linux64/<NAME>.so, with IPMSM_WIN64
#                             also binaries/win64/<NAME>.dll, resources/, documentation/) and zips
#                             it to ${CMAKE_BINARY_DIR}/fmu/<NAME>.fmu, again whenever a library,
#                             the generator, a resource, the documentation or this file changes.
#
# With IPMSM_WIN64=ON, every FMU's Windows DLL comes from the cross build in
# ${CMAKE_BINARY_DIR}/win64 (cmake/win64.cmake: the same sources, configured with
# cmake/mingw-w64-x86_64.cmake). There, add_fmu() builds only <NAME>.dll: linked with -static (it
# imports only KERNEL32 and msvcrt), exporting exactly the fmi2* functions that fmi2Functions.h
# declares __declspec(dllexport) (tests/python/test_conformance.py checks both).
#
# FMI 3: the same, for the FMI 3.0 co-simulation FMU of the same model, its SOURCES including
# fmi3_entry_points.inc: the target <NAME>_fmi3 (the library still named <NAME>, in its own
# directory), exporting the fmi3* functions only (fmu_src/fmi/exports3.map), the generator
# <NAME>_fmi3_modelDescription (IPMSM_FMI3_GENERATOR), packed to ${CMAKE_BINARY_DIR}/fmu3/<NAME>.fmu
# with FMI 3.0's platform folders binaries/x86_64-linux/ and binaries/x86_64-windows/.
#
# This file is also the assembly script: `cmake -DFMU_CONFIG=<file> -P add_fmu.cmake`.

if(CMAKE_SCRIPT_MODE_FILE)
  # NAME, DIR, FMU, LIBRARY, WIN64_LIBRARY, LINUX_PLATFORM, WIN64_PLATFORM, GENERATOR, RESOURCES, DOCUMENTATION
  include(${FMU_CONFIG})
  file(REMOVE_RECURSE ${DIR})
  file(MAKE_DIRECTORY ${DIR}/binaries/${LINUX_PLATFORM} ${DIR}/resources)
  set(html_args)
  if(DOCUMENTATION)
    set(html_args --html ${DIR}.variables.html)
  endif()
  execute_process(COMMAND ${GENERATOR} ${DIR}/modelDescription.xml ${html_args} RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${NAME}: the modelDescription.xml generator failed (${rc})")
  endif()
  file(COPY_FILE ${LIBRARY} ${DIR}/binaries/${LINUX_PLATFORM}/${NAME}.so)
  if(WIN64_LIBRARY)
    file(MAKE_DIRECTORY ${DIR}/binaries/${WIN64_PLATFORM})
    file(COPY_FILE ${WIN64_LIBRARY} ${DIR}/binaries/${WIN64_PLATFORM}/${NAME}.dll)
  endif()
  foreach(r IN LISTS RESOURCES)
    get_filename_component(r_name ${r} NAME)
    file(COPY_FILE ${r} ${DIR}/resources/${r_name})
  endforeach()
  set(entries modelDescription.xml binaries resources)
  if(DOCUMENTATION)
    # the documentation, with the generated variable reference at <!-- ipmsm-fmu:variables -->
    file(READ ${DIR}.variables.html variables_html)
    file(REMOVE ${DIR}.variables.html)
    file(MAKE_DIRECTORY ${DIR}/documentation)
    file(READ ${DOCUMENTATION} html)
    string(FIND "${html}" "<!-- ipmsm-fmu:variables -->" at)
    if(at LESS 0)
      message(FATAL_ERROR "${NAME}: ${DOCUMENTATION} has no <!-- ipmsm-fmu:variables --> marker")
    endif()
    string(REPLACE "<!-- ipmsm-fmu:variables -->" "${variables_html}" html "${html}")
    file(WRITE ${DIR}/documentation/index.html "${html}")
    list(APPEND entries documentation)
  endif()
  file(REMOVE ${FMU})
  execute_process(
    COMMAND ${CMAKE_COMMAND} -E tar cf ${FMU}.tmp --format=zip "--mtime=2000-01-01 00:00:00 UTC" -- ${entries}
    WORKING_DIRECTORY ${DIR} RESULT_VARIABLE rc)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "${NAME}: zipping ${DIR} failed (${rc})")
  endif()
  file(RENAME ${FMU}.tmp ${FMU})
  return()
endif()

set(IPMSM_ADD_FMU_SCRIPT ${CMAKE_CURRENT_LIST_FILE})
set(IPMSM_FMI2_EXPORTS_MAP ${CMAKE_CURRENT_LIST_DIR}/../fmu_src/fmi/exports.map)
set(IPMSM_FMI3_EXPORTS_MAP ${CMAKE_CURRENT_LIST_DIR}/../fmu_src/fmi/exports3.map)
set(IPMSM_FMI2_GLIBC_COMPAT ${CMAKE_CURRENT_LIST_DIR}/../fmu_src/fmi/glibc_compat.cpp)

function(add_fmu)
  cmake_parse_arguments(PARSE_ARGV 0 FMU "" "NAME;DOCUMENTATION" "FMI;SOURCES;LIBRARIES;RESOURCES")
  if(NOT FMU_NAME OR NOT FMU_SOURCES)
    message(FATAL_ERROR "add_fmu: NAME and SOURCES are required")
  endif()
  if(NOT FMU_FMI)
    set(FMU_FMI 2)
  endif()
  foreach(fmi IN LISTS FMU_FMI)
    string(REPLACE "@FMI@" "${fmi}" sources "${FMU_SOURCES}")
    _add_fmu_for_standard(${fmi} "${sources}")
  endforeach()
endfunction()

# One standard's FMU of add_fmu()'s model (its arguments, FMU_*, are in the caller's scope).
function(_add_fmu_for_standard standard sources)
  set(name ${FMU_NAME})
  set(FMU_SOURCES ${sources})
  # Per standard: the target, the generator's define, the exported symbols, where the FMU goes and
  # its binaries' platform folders.
  if(standard STREQUAL "2")
    set(target ${name})
    set(generator_define IPMSM_FMI2_GENERATOR)
    set(exports_map ${IPMSM_FMI2_EXPORTS_MAP})
    set(fmu_dir ${CMAKE_BINARY_DIR}/fmu)
    set(output_subdir "")
    set(linux_platform linux64)
    set(win64_platform win64)
  elseif(standard STREQUAL "3")
    set(target ${name}_fmi3)
    set(generator_define IPMSM_FMI3_GENERATOR)
    set(exports_map ${IPMSM_FMI3_EXPORTS_MAP})
    set(fmu_dir ${CMAKE_BINARY_DIR}/fmu3)
    set(output_subdir /fmi3)  # beside the FMI 2.0 library of the same name
    set(linux_platform x86_64-linux)
    set(win64_platform x86_64-windows)
  else()
    message(FATAL_ERROR "add_fmu: FMI must be 2 or 3, not ${standard}")
  endif()
  set(resources "")
  foreach(r IN LISTS FMU_RESOURCES)
    get_filename_component(r ${r} ABSOLUTE)
    list(APPEND resources ${r})
  endforeach()
  set(documentation "")
  if(FMU_DOCUMENTATION)
    get_filename_component(documentation ${FMU_DOCUMENTATION} ABSOLUTE)
  endif()

  if(WIN32)  # the win64 cross build: the DLL only, packed by the Linux build
    add_library(${target} SHARED ${FMU_SOURCES})
    target_link_libraries(${target} PRIVATE fmi2_glue ${FMU_LIBRARIES})
    set_target_properties(${target} PROPERTIES PREFIX "" OUTPUT_NAME ${name} SUFFIX ".dll"
      RUNTIME_OUTPUT_DIRECTORY ${CMAKE_RUNTIME_OUTPUT_DIRECTORY}${output_subdir}
      ARCHIVE_OUTPUT_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR}${output_subdir}  # the import library
      C_VISIBILITY_PRESET hidden CXX_VISIBILITY_PRESET hidden VISIBILITY_INLINES_HIDDEN ON)
    target_compile_options(${target} PRIVATE -ffunction-sections -fdata-sections)
    # -static: libstdc++, libgcc and winpthread inside (-static-libgcc -static-libstdc++ alone
    # still leave libwinpthread-1.dll); --strip-debug: the mingw runtime's DWARF (half the DLL).
    target_link_options(${target} PRIVATE -static "LINKER:--gc-sections" "LINKER:--no-undefined"
      "LINKER:--strip-debug")
    set_target_properties(${target} PROPERTIES IMPORT_PREFIX "" IMPORT_SUFFIX ".dll.a")
    # The generator and <target>_fmu exist as in the Linux build (for CMake code that names them),
    # but only the DLL is built: the Linux build writes modelDescription.xml and packs the FMU.
    add_executable(${target}_modelDescription EXCLUDE_FROM_ALL ${FMU_SOURCES})
    target_link_libraries(${target}_modelDescription PRIVATE fmi2_glue ${FMU_LIBRARIES})
    target_compile_definitions(${target}_modelDescription PRIVATE
      ${generator_define} IPMSM_FMU_VERSION="${PROJECT_VERSION}")
    add_custom_target(${target}_fmu ALL DEPENDS ${target})
    return()
  endif()

  # The FMU's shared library.
  add_library(${target} SHARED ${FMU_SOURCES})
  target_link_libraries(${target} PRIVATE fmi2_glue ${FMU_LIBRARIES})
  set_target_properties(${target} PROPERTIES
    PREFIX "" OUTPUT_NAME ${name} SUFFIX ".so"
    LIBRARY_OUTPUT_DIRECTORY ${CMAKE_CURRENT_BINARY_DIR}${output_subdir}
    C_VISIBILITY_PRESET hidden CXX_VISIBILITY_PRESET hidden VISIBILITY_INLINES_HIDDEN ON
    LINK_DEPENDS ${exports_map})
  target_compile_options(${target} PRIVATE -ffunction-sections -fdata-sections)
  target_link_options(${target} PRIVATE "LINKER:--version-script=${exports_map}" "LINKER:--gc-sections")
  if(NOT IPMSM_SANITIZE)  # the sanitizer runtimes are shared libraries with undefined hooks
    # libstdc++ static (a target's own may be older than GCC 12's); libgcc_s.so.1 shared: a static
    # libgcc's unwinder calls _dl_find_object (GLIBC_2.35). glibc_compat.cpp pins the rest.
    target_sources(${target} PRIVATE ${IPMSM_FMI2_GLIBC_COMPAT})
    target_link_options(${target} PRIVATE "LINKER:--no-undefined" -static-libstdc++ -shared-libgcc
      "LINKER:--wrap=hypot,--wrap=exp,--wrap=log,--wrap=pow,--wrap=stat,--wrap=fstat64,--wrap=pthread_once")
  endif()

  # The modelDescription.xml generator: the same sources, the entry points define main().
  add_executable(${target}_modelDescription ${FMU_SOURCES})
  target_link_libraries(${target}_modelDescription PRIVATE fmi2_glue ${FMU_LIBRARIES})
  target_compile_definitions(${target}_modelDescription PRIVATE
    ${generator_define} IPMSM_FMU_VERSION="${PROJECT_VERSION}")

  # Assembly and zip.
  set(dir ${fmu_dir}/${name})
  set(fmu ${fmu_dir}/${name}.fmu)
  set(config ${CMAKE_CURRENT_BINARY_DIR}/${target}_fmu_config.cmake)
  set(win64_library "")
  if(IPMSM_WIN64)
    set(win64_library ${IPMSM_WIN64_BINARY_DIR}/bin${output_subdir}/${name}.dll)
    set_property(GLOBAL APPEND PROPERTY IPMSM_WIN64_FMUS ${target})
    set_property(GLOBAL APPEND PROPERTY IPMSM_WIN64_DLLS ${win64_library})
  endif()
  file(GENERATE OUTPUT ${config} CONTENT
"set(NAME \"${name}\")
set(DIR \"${dir}\")
set(FMU \"${fmu}\")
set(LIBRARY \"$<TARGET_FILE:${target}>\")
set(WIN64_LIBRARY \"${win64_library}\")
set(LINUX_PLATFORM \"${linux_platform}\")
set(WIN64_PLATFORM \"${win64_platform}\")
set(GENERATOR \"$<TARGET_FILE:${target}_modelDescription>\")
set(RESOURCES \"${resources}\")
set(DOCUMENTATION \"${documentation}\")
")
  add_custom_command(
    OUTPUT ${fmu}
    COMMAND ${CMAKE_COMMAND} -DFMU_CONFIG=${config} -P ${IPMSM_ADD_FMU_SCRIPT}
    DEPENDS ${target} ${target}_modelDescription ${win64_library} ${resources} ${documentation} ${config} ${IPMSM_ADD_FMU_SCRIPT}
    COMMENT "Packaging FMU ${fmu}"
    VERBATIM)
  add_custom_target(${target}_fmu ALL DEPENDS ${fmu})
endfunction()
