# IPMSM_WIN64: every FMU also carries binaries/win64/<NAME>.dll. The Windows half is a second
# CMake build of this same source tree in ${CMAKE_BINARY_DIR}/win64, cross-compiled with mingw-w64
# (cmake/mingw-w64-x86_64.cmake) against the cross-built SUNDIALS of scripts/setup_win64.sh
# (IPMSM_WIN64_SUNDIALS_DIR), run as an external project of the Linux build: add_fmu() records
# each FMU, ipmsm_add_win64_build() (at the end of the top-level CMakeLists.txt, once every FMU
# is known) declares their DLLs as what the cross build produces, so that the Linux packaging of
# an FMU re-runs when its DLL changes. The cross build also gives the wine tests their programs
# (build/win64/bin/unit_tests.exe, fmi2_harness.exe; tests/python/test_win64.py).
option(IPMSM_WIN64 "Also build every FMU's win64 binary (mingw-w64 cross build, tested under wine)" OFF)
set(IPMSM_WIN64_BINARY_DIR ${CMAKE_BINARY_DIR}/win64)

if(IPMSM_WIN64 AND NOT CMAKE_CROSSCOMPILING)
  if(NOT IPMSM_WIN64_SUNDIALS_DIR)
    set(IPMSM_WIN64_SUNDIALS_DIR $ENV{IPMSM_WIN64_SUNDIALS_DIR})
  endif()
  set(IPMSM_WIN64_SUNDIALS_DIR ${IPMSM_WIN64_SUNDIALS_DIR} CACHE PATH
    "Windows SUNDIALS (static), built by scripts/setup_win64.sh" FORCE)
  if(NOT EXISTS ${IPMSM_WIN64_SUNDIALS_DIR}/include/cvode/cvode.h)
    message(FATAL_ERROR "IPMSM_WIN64=ON needs the Windows SUNDIALS: run scripts/setup_win64.sh "
      "(scripts/setup.sh does), or configure with -DIPMSM_WIN64=OFF")
  endif()
  find_program(IPMSM_MINGW_CXX x86_64-w64-mingw32-g++-posix REQUIRED)
endif()

function(ipmsm_add_win64_build)
  if(NOT IPMSM_WIN64 OR CMAKE_CROSSCOMPILING)
    return()
  endif()
  get_property(fmus GLOBAL PROPERTY IPMSM_WIN64_FMUS)  # add_fmu's targets, FMI 2.0 and 3.0
  get_property(byproducts GLOBAL PROPERTY IPMSM_WIN64_DLLS)  # their DLLs
  set(launchers "")
  if(CMAKE_CXX_COMPILER_LAUNCHER)
    list(APPEND launchers -DCMAKE_C_COMPILER_LAUNCHER=${CMAKE_CXX_COMPILER_LAUNCHER}
                          -DCMAKE_CXX_COMPILER_LAUNCHER=${CMAKE_CXX_COMPILER_LAUNCHER})
  endif()
  include(ExternalProject)
  ExternalProject_Add(win64
    SOURCE_DIR ${PROJECT_SOURCE_DIR}
    BINARY_DIR ${IPMSM_WIN64_BINARY_DIR}
    CMAKE_GENERATOR ${CMAKE_GENERATOR}
    CMAKE_ARGS
      -DCMAKE_TOOLCHAIN_FILE=${PROJECT_SOURCE_DIR}/cmake/mingw-w64-x86_64.cmake
      -DIPMSM_WIN64_SUNDIALS_DIR=${IPMSM_WIN64_SUNDIALS_DIR}
      -DCMAKE_BUILD_TYPE=${CMAKE_BUILD_TYPE}
      -DFMI2_INCLUDE_DIR=${FMI2_INCLUDE_DIR}
      -DEigen3_DIR=${Eigen3_DIR}
      -DIPMSM_BUILD_TESTS=${IPMSM_BUILD_TESTS}
      -DIPMSM_BUILD_BENCH=OFF -DIPMSM_SANITIZE=OFF -DIPMSM_WIN64=OFF
      ${launchers}
    CONFIGURE_HANDLED_BY_BUILD ON  # after the first configure, the inner build re-runs CMake itself
    INSTALL_COMMAND ""
    BUILD_ALWAYS ON  # the inner build decides what is out of date
    BUILD_BYPRODUCTS ${byproducts}
    LOG_CONFIGURE ON LOG_OUTPUT_ON_FAILURE ON  # the inner configure's chatter in win64-prefix/
    USES_TERMINAL_BUILD ON)
  foreach(name IN LISTS fmus)
    add_dependencies(${name}_fmu win64)
  endforeach()
endfunction()
