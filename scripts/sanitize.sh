#!/usr/bin/env bash
# The AddressSanitizer + UBSan build (issue 5): a second build tree, build-asan/, with
# IPMSM_SANITIZE=ON at -O1 (the sanitizers' usual level: quick to build, still fast to run).
#
#   scripts/sanitize.sh          the FMUs (IpmsmController, IpmsmPlant, IpmsmDrive, ToyLag) and the fuzz
#                                harness: what tests/python/test_sanitizers.py runs by default
#   scripts/sanitize.sh --full   everything, the C++ unit tests too (the slow full pass)
#
# ./test.sh runs it in its build stage; tests/python/test_sanitizers.py then runs, under ASan and
# UBSan, the fuzz harness and the pytest modules that load the FMUs (default), or ctest and the
# whole pytest suite (`./test.sh -m slow`). By hand, after this script:
#   LD_PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libstdc++.so)" \
#   ASAN_OPTIONS=detect_leaks=0 IPMSM_FMU_DIR=build-asan/fmu python -m pytest tests/python -k "not valgrind"
# (Python is not instrumented: ASan must be preloaded, with libstdc++ so that it can intercept C++
# exceptions; the interpreter's own allocations are not leak-checked, the C harness is.)
set -euo pipefail
_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
_build=${IPMSM_ASAN_BUILD:-$_root/build-asan}
_python=$(command -v python || command -v python3)
source "$_root/scripts/compiler_cache.sh" ""

if [ ! -f "$_build/CMakeCache.txt" ]; then
  echo "[sanitize] configuring $_build (AddressSanitizer + UBSan, -O1)"
  cmake -S "$_root" -B "$_build" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG=-O1 \
    -DCMAKE_C_FLAGS_DEBUG=-O1 -DIPMSM_SANITIZE=ON -DIPMSM_BUILD_BENCH=OFF \
    -DPython3_EXECUTABLE="$_python" >/dev/null
fi
if [ "${1:-}" = "--full" ]; then
  echo "[sanitize] building everything in $_build"
  cmake --build "$_build" --parallel "$(nproc)"
else
  echo "[sanitize] building the FMUs and the fuzz harness in $_build"
  cmake --build "$_build" --parallel "$(nproc)" --target IpmsmController_fmu IpmsmPlant_fmu IpmsmDrive_fmu ToyLag_fmu fmu_fuzz \
    IpmsmController_fmi3_fmu IpmsmPlant_fmi3_fmu IpmsmDrive_fmi3_fmu
fi
