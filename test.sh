#!/usr/bin/env bash
# Every test: set up and build (as run.sh, plus the AddressSanitizer/UBSan build in build-asan/),
# then the C++ unit tests (ctest) and the Python system tests (pytest; they include the runs on
# the sanitizer build, tests/python/test_sanitizers.py; long runs are behind the `slow` marker:
# ./test.sh -m slow). Idempotent.
set -euo pipefail
cd "$(dirname "$0")"
source scripts/setup.sh
bash scripts/sanitize.sh
echo "[test] C++ unit tests"
ctest --test-dir build --output-on-failure -j "$(nproc)"
echo "[test] Python system tests"
IPMSM_REQUIRE_SANITIZERS=1 python -m pytest tests/python -m "${PYTEST_MARK:-not slow}" "$@"
