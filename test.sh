#!/usr/bin/env bash
# Every test: set up and build (as run.sh), then the C++ unit tests (ctest) and the Python
# system tests (pytest; long runs are behind the `slow` marker: ./test.sh -m slow). Idempotent.
set -euo pipefail
cd "$(dirname "$0")"
source scripts/setup.sh
echo "[test] C++ unit tests"
ctest --test-dir build --output-on-failure -j "$(nproc)"
echo "[test] Python system tests"
python -m pytest tests/python -m "${PYTEST_MARK:-not slow}" "$@"
