# Third-party dependencies, all from the distribution (Debian: libeigen3-dev, libsundials-dev,
# libgtest-dev) or from the Python venv (the FMI 2.0 headers that ship inside the fmpy wheel).

find_package(Eigen3 3.3 REQUIRED NO_MODULE)

# SUNDIALS: link the static archives so that the FMU binary needs no libsundials at run time.
set(_sundials_components cvode nvecserial sunlinsoldense sunmatrixdense sunnonlinsolnewton sunnonlinsolfixedpoint)
set(SUNDIALS_STATIC_LIBRARIES "")
foreach(c IN LISTS _sundials_components)
  find_library(SUNDIALS_${c}_LIB NAMES libsundials_${c}.a REQUIRED)
  list(APPEND SUNDIALS_STATIC_LIBRARIES ${SUNDIALS_${c}_LIB})
endforeach()
find_path(SUNDIALS_INCLUDE_DIR cvode/cvode.h REQUIRED)
add_library(sundials_static INTERFACE)
target_include_directories(sundials_static SYSTEM INTERFACE ${SUNDIALS_INCLUDE_DIR})
target_link_libraries(sundials_static INTERFACE ${SUNDIALS_STATIC_LIBRARIES} m)

# FMI 2.0 headers: from the fmpy package (fmpy/c-code), not copied into this repository (the
# win64 cross build is given the Linux build's FMI2_INCLUDE_DIR).
if(NOT FMI2_INCLUDE_DIR)
  find_package(Python3 REQUIRED COMPONENTS Interpreter)
  execute_process(
    COMMAND ${Python3_EXECUTABLE} -c "import fmpy, os; print(os.path.join(os.path.dirname(fmpy.__file__), 'c-code'))"
    OUTPUT_VARIABLE FMI2_INCLUDE_DIR OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE _fmpy_rc)
endif()
if(NOT EXISTS ${FMI2_INCLUDE_DIR}/fmi2Functions.h)
  message(FATAL_ERROR "FMI 2.0 headers not found: install fmpy in ${Python3_EXECUTABLE} (scripts/setup.sh does)")
endif()
add_library(fmi2_headers INTERFACE)
target_include_directories(fmi2_headers SYSTEM INTERFACE ${FMI2_INCLUDE_DIR})

if(IPMSM_BUILD_TESTS)
  if(CMAKE_CROSSCOMPILING)
    # No Windows GoogleTest in the distribution: build libgtest-dev's sources (/usr/src/googletest).
    set(INSTALL_GTEST OFF CACHE BOOL "" FORCE)
    set(BUILD_GMOCK OFF CACHE BOOL "" FORCE)
    add_subdirectory(/usr/src/googletest ${CMAKE_BINARY_DIR}/googletest EXCLUDE_FROM_ALL)
    if(NOT TARGET GTest::gtest_main)  # googletest 1.12's own CMake defines these aliases
      add_library(GTest::gtest ALIAS gtest)
      add_library(GTest::gtest_main ALIAS gtest_main)
    endif()
  else()
    find_package(GTest REQUIRED)
  endif()
endif()
