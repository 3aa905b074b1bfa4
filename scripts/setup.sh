#!/usr/bin/env bash
# Idempotent set-up on a fresh Debian/Ubuntu machine: system packages, a Python venv with the
# project installed editable (pyproject.toml, through requirements.txt), the win64 cross toolchain
# and wine (scripts/setup_win64.sh; skipped with IPMSM_WIN64=OFF), then CMake configure + build.
# Sourced by run.sh and test.sh: it takes no arguments (callers `set --` before sourcing).
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$ROOT"

say() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }

# --- system packages (Debian names) ---
APT_PACKAGES=(build-essential cmake ninja-build libeigen3-dev libsundials-dev libgtest-dev valgrind maven
              clang-format  # the lint step of test.sh
              ccache)       # compiler cache: a fresh clone rebuilds from it (scripts/compiler_cache.sh)
missing=()
for p in "${APT_PACKAGES[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if [ ${#missing[@]} -gt 0 ]; then
  say "installing system packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# --- Python venv ---
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  say "creating .venv"
  if ! "$PY" -m venv .venv 2>/dev/null; then
    SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get install -y -qq python3-venv >/dev/null
    rm -rf .venv; "$PY" -m venv .venv
  fi
fi
# reinstall when the declared dependencies change (pyproject.toml or requirements.txt)
declared=$(cat requirements.txt pyproject.toml | sha256sum)
if [ "$declared" != "$(cat .venv/.requirements.installed 2>/dev/null)" ]; then
  say "installing the Python side (pip install -e .[test])"
  # setuptools >= 70.1 in the venv: the wheel's build (cmake/wheel.cmake) runs without isolation
  .venv/bin/python -m pip install -q --upgrade pip "setuptools>=70.1" >/dev/null
  .venv/bin/python -m pip install -q -r requirements.txt
  echo "$declared" > .venv/.requirements.installed
fi
export PATH="$ROOT/.venv/bin:$PATH"

# --- VDMCheck2 (FMI 2.0 model-description checker, Maven Central) -> build-tools/, for the tests ---
# (an explicit empty argument: the default destination, whatever the caller's arguments are)
source scripts/install_vdmcheck2.sh ""

# --- compiler cache (ccache) for every build below and scripts/sanitize.sh's ---
source scripts/compiler_cache.sh ""

# --- win64: mingw-w64, wine, the Windows SUNDIALS (scripts/setup_win64.sh); IPMSM_WIN64=OFF skips ---
case "${IPMSM_WIN64:-ON}" in OFF|off|0|NO|no|FALSE|false) IPMSM_WIN64=OFF ;; *) IPMSM_WIN64=ON ;; esac
export IPMSM_WIN64
WIN64_ARGS=(-DIPMSM_WIN64="$IPMSM_WIN64")
if [ "$IPMSM_WIN64" = ON ]; then
  source scripts/setup_win64.sh ""  # explicit (empty) arguments: it never sees a caller's
  WIN64_ARGS+=(-DIPMSM_WIN64_SUNDIALS_DIR="$IPMSM_WIN64_SUNDIALS_DIR")
fi

# --- build ---
BUILD_TYPE=${BUILD_TYPE:-Release}
if [ ! -f build/CMakeCache.txt ]; then
  say "configuring (CMake, $BUILD_TYPE)"
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE="$BUILD_TYPE" -DPython3_EXECUTABLE="$ROOT/.venv/bin/python" \
    "${WIN64_ARGS[@]}" >/dev/null
elif ! grep -qx "IPMSM_WIN64:BOOL=$IPMSM_WIN64" build/CMakeCache.txt; then
  say "reconfiguring with IPMSM_WIN64=$IPMSM_WIN64"
  cmake -B build "${WIN64_ARGS[@]}" >/dev/null
fi
say "building"
cmake --build build --parallel "$(nproc)"
