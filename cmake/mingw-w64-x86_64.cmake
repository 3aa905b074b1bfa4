# CMake toolchain for Windows x86-64 with Debian's mingw-w64 (g++-mingw-w64-x86-64-posix: the
# posix thread model, so that <thread> and <mutex> work). Programs built with it (the model
# description generators, the unit tests, the wine harness) run under wine.
#
# IPMSM_WIN64_SUNDIALS_DIR: the cross-built SUNDIALS (scripts/setup_win64.sh). It goes into
# CMAKE_FIND_ROOT_PATH: libraries and headers are searched in ONLY mode, where CMAKE_PREFIX_PATH
# is not searched, so that no Linux library can be picked up by mistake.
set(CMAKE_SYSTEM_NAME Windows)
set(CMAKE_SYSTEM_PROCESSOR x86_64)
set(CMAKE_C_COMPILER x86_64-w64-mingw32-gcc-posix)
set(CMAKE_CXX_COMPILER x86_64-w64-mingw32-g++-posix)
set(CMAKE_RC_COMPILER x86_64-w64-mingw32-windres)

# Programs self-contained (libstdc++, libgcc, winpthread inside): wine finds no mingw DLLs.
set(CMAKE_EXE_LINKER_FLAGS_INIT -static)

list(APPEND CMAKE_TRY_COMPILE_PLATFORM_VARIABLES IPMSM_WIN64_SUNDIALS_DIR)
set(CMAKE_FIND_ROOT_PATH /usr/x86_64-w64-mingw32 ${IPMSM_WIN64_SUNDIALS_DIR})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE ONLY)

find_program(IPMSM_WINE NAMES wine wine64)
if(IPMSM_WINE)
  set(CMAKE_CROSSCOMPILING_EMULATOR ${IPMSM_WINE})
endif()
