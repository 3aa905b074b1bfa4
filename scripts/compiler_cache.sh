#!/usr/bin/env bash
# Compiler caching for every build of the set-up (build/, its win64 cross build, build-asan/, the
# Windows SUNDIALS): sourced by scripts/setup.sh and scripts/sanitize.sh before they configure.
# With ccache installed (scripts/setup.sh installs it), CMake's compiler launcher is ccache, and
# CCACHE_BASEDIR is the repository's root: ccache then hashes paths relative to it, so that a
# fresh clone in another folder reuses what an earlier clone compiled (the objects are the same:
# no absolute path of the clone reaches a compiled file but through IPMSM_SOURCE_DIR, which only
# the tests that read the source tree are given, tests/CMakeLists.txt).
# A caller's own choice wins: CMAKE_CXX_COMPILER_LAUNCHER set (empty: no launcher) is kept, and
# so is CCACHE_BASEDIR. The launcher only matters when a build folder is first configured.
if [ -z "${CMAKE_CXX_COMPILER_LAUNCHER+set}" ] && command -v ccache >/dev/null 2>&1; then
  export CMAKE_C_COMPILER_LAUNCHER=ccache CMAKE_CXX_COMPILER_LAUNCHER=ccache
fi
if [ "${CMAKE_CXX_COMPILER_LAUNCHER:-}" = ccache ]; then
  export CCACHE_BASEDIR=${CCACHE_BASEDIR:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)}
fi
