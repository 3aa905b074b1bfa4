#!/usr/bin/env bash
# Every test: set up and build (as run.sh, plus the AddressSanitizer/UBSan build in build-asan/),
# the lint step (scripts/lint.sh: ruff, clang-format), then the C++ unit tests (ctest) and the
# Python system tests (pytest; they include the runs on the sanitizer build,
# tests/python/test_sanitizers.py). Idempotent.
#
# Arguments go to pytest: ./test.sh -m slow (the long runs: full drive cycles, the whole suite
# under ASan and valgrind), ./test.sh -k conformance, ./test.sh -x -q ... Without a -m of its own,
# pytest runs -m "not slow".
set -euo pipefail
cd "$(dirname "$0")"
pytest_args=("$@")
has_mark=0
for a in "${pytest_args[@]}"; do
  case "$a" in -m|-m*|--mark*) has_mark=1 ;; esac
done
# The set-up scripts are sourced: they must not see this script's arguments.
set --
source scripts/setup.sh
bash scripts/sanitize.sh
echo "[test] lint"
lint_status=0
bash scripts/lint.sh || lint_status=$?  # reported at the end: a style slip does not hide test results
echo "[test] C++ unit tests"
ctest --test-dir build --output-on-failure -j "$(nproc)"
echo "[test] Python system tests"
if [ "$has_mark" = 0 ]; then
  pytest_args=(-m "not slow" "${pytest_args[@]}")
fi
IPMSM_REQUIRE_SANITIZERS=1 python -m pytest tests/python "${pytest_args[@]}"
if [ "$lint_status" != 0 ]; then
  echo "[test] the tests passed but the lint step failed (above; scripts/format_all.sh fixes most)" >&2
  exit "$lint_status"
fi
