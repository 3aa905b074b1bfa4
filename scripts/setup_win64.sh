#!/usr/bin/env bash
# The Windows (win64) half of the set-up, sourced by scripts/setup.sh unless IPMSM_WIN64=OFF:
#   1. the cross toolchain and wine (Debian: g++-mingw-w64-x86-64-posix, wine64, wine), and a
#      wine prefix initialised once (wineboot) so that the first test run does not pay for it;
#   2. SUNDIALS for Windows, built once from Debian's own source package of the same version as
#      libsundials-dev (so both platforms integrate with the same CVODE): static libraries, CVODE
#      with its serial vector, dense matrix/solver and Newton/fixed-point solvers only, installed
#      to build-win64-deps/sundials-<version>/ (outside build/, it survives `rm -rf build`).
#      A third-party build, kept once per machine as pip keeps its wheels: the first clone puts it
#      in ${XDG_CACHE_HOME:-~/.cache}/ipmsm-fmu/win64-sundials-<version>-<key>, later clones copy
#      it. The key hashes what determines the build (the cross compiler's version, the toolchain
#      file, this script); the cache is written whole, then renamed into place.
# Exports IPMSM_WIN64_SUNDIALS_DIR for the CMake configure (cmake/add_fmu.cmake builds the DLLs).
# Idempotent; about a minute the first time (plus the packages' download), nothing afterwards.
set -euo pipefail
_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
_say() { printf '\033[1m[setup win64]\033[0m %s\n' "$*"; }
_sudo=""; [ "$(id -u)" -eq 0 ] || _sudo="sudo"

# --- 1. packages: the posix thread model, so that std::thread/std::mutex exist ---
_missing=()
for p in g++-mingw-w64-x86-64-posix wine64 wine dpkg-dev; do
  dpkg -s "$p" >/dev/null 2>&1 || _missing+=("$p")
done
if [ ${#_missing[@]} -gt 0 ]; then
  _say "installing ${_missing[*]} (about 1.3 GB)"
  $_sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $_sudo apt-get install -y -qq "${_missing[@]}" >/dev/null
fi
export WINEDEBUG=${WINEDEBUG:--all}
if [ ! -f "${WINEPREFIX:-$HOME/.wine}/system.reg" ]; then
  _say "initialising the wine prefix (wineboot)"
  wineboot -i >/dev/null 2>&1 || true
  wineserver -w || true
fi

# --- 2. SUNDIALS for Windows, from Debian's source package of libsundials-dev's version ---
_version=$(dpkg-query -W -f='${Version}' libsundials-dev)
_upstream=${_version%%+*}; _upstream=${_upstream%%-*}
_deps=$_root/build-win64-deps
export IPMSM_WIN64_SUNDIALS_DIR=$_deps/sundials-$_version
_key=$({ dpkg-query -W gcc-mingw-w64-x86-64-posix g++-mingw-w64-x86-64-posix; x86_64-w64-mingw32-gcc-posix --version
         cat "$_root/cmake/mingw-w64-x86_64.cmake" "${BASH_SOURCE[0]}"; } | sha256sum | cut -c1-16)
_cached=${XDG_CACHE_HOME:-$HOME/.cache}/ipmsm-fmu/win64-sundials-$_version-$_key
if [ ! -f "$IPMSM_WIN64_SUNDIALS_DIR/.complete" ] && [ -f "$_cached/.complete" ]; then
  _say "SUNDIALS $_version for Windows from this machine's cache ($_cached)"
  rm -rf "$IPMSM_WIN64_SUNDIALS_DIR" "$IPMSM_WIN64_SUNDIALS_DIR.partial"
  mkdir -p "$_deps"
  cp -a "$_cached" "$IPMSM_WIN64_SUNDIALS_DIR.partial"
  mv -T "$IPMSM_WIN64_SUNDIALS_DIR.partial" "$IPMSM_WIN64_SUNDIALS_DIR"
fi
if [ ! -f "$IPMSM_WIN64_SUNDIALS_DIR/.complete" ]; then
  _src=$_deps/src
  if [ ! -d "$_src/sundials-$_upstream" ]; then
    if ! apt-get source --print-uris "sundials=$_version" >/dev/null 2>&1; then
      # apt-get source needs a deb-src entry for the distribution's own archive.
      _say "adding the deb-src entry of the distribution's archive (for apt-get source sundials)"
      . /etc/os-release
      printf 'Types: deb-src\nURIs: http://deb.debian.org/debian\nSuites: %s\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
        "$VERSION_CODENAME" | $_sudo tee /etc/apt/sources.list.d/ipmsm-fmu-deb-src.sources >/dev/null
      $_sudo apt-get update -qq
    fi
    _say "fetching Debian's source package sundials=$_version"
    rm -rf "$_src"; mkdir -p "$_src"
    (cd "$_src" && apt-get source -qq "sundials=$_version" >/dev/null)
    mv "$_src"/sundials-"$_upstream"* "$_src/sundials-$_upstream" 2>/dev/null || true
  fi
  _say "cross-building SUNDIALS $_version (static, CVODE only)"
  rm -rf "$_deps/sundials-build" "$IPMSM_WIN64_SUNDIALS_DIR"
  _log=$_deps/sundials-build.log
  trap 'echo "[setup win64] the SUNDIALS cross build failed: see $_log" >&2' ERR
  cmake -S "$_src/sundials-$_upstream" -B "$_deps/sundials-build" -G Ninja \
    -DCMAKE_TOOLCHAIN_FILE="$_root/cmake/mingw-w64-x86_64.cmake" -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_INSTALL_PREFIX="$IPMSM_WIN64_SUNDIALS_DIR" \
    -DBUILD_STATIC_LIBS=ON -DBUILD_SHARED_LIBS=OFF \
    -DBUILD_ARKODE=OFF -DBUILD_CVODES=OFF -DBUILD_IDA=OFF -DBUILD_IDAS=OFF -DBUILD_KINSOL=OFF \
    -DBUILD_CVODE=ON -DBUILD_FORTRAN_MODULE_INTERFACE=OFF \
    -DEXAMPLES_ENABLE_C=OFF -DEXAMPLES_ENABLE_CXX=OFF -DEXAMPLES_INSTALL=OFF >"$_log" 2>&1
  cmake --build "$_deps/sundials-build" --parallel "$(nproc)" >>"$_log" 2>&1
  cmake --install "$_deps/sundials-build" >>"$_log" 2>&1
  trap - ERR
  touch "$IPMSM_WIN64_SUNDIALS_DIR/.complete"
  # into the machine's cache: a whole copy renamed into place (a concurrent set-up's copy may win)
  if mkdir -p "$(dirname "$_cached")" 2>/dev/null \
     && _tmp=$(mktemp -d "$(dirname "$_cached")/.win64-sundials.XXXXXX" 2>/dev/null); then
    { cp -a "$IPMSM_WIN64_SUNDIALS_DIR/." "$_tmp/" && mv -T "$_tmp" "$_cached"; } 2>/dev/null || rm -rf "$_tmp"
  fi
fi
