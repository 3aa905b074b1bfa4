#!/usr/bin/env bash
# Applies the project's formatting to the whole tree, once, after a merge: ruff's automatic fixes
# (import order, pyupgrade rewrites; pyproject.toml [tool.ruff]) and clang-format -i on every
# C/C++ source (.clang-format). Then scripts/lint.sh lists what remains for a human (ruff rules
# without an automatic fix). Review the diff before committing it.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
ruff check --fix . || true
mapfile -t cxx < <(bash scripts/cxx_sources.sh)
clang-format -i "${cxx[@]}"
bash scripts/lint.sh
