#!/usr/bin/env bash
# The lint step of test.sh: ruff on every Python file (rules in pyproject.toml [tool.ruff]) and
# clang-format on every C/C++ source (style in .clang-format), both as checks that change nothing.
# scripts/format_all.sh applies both. Needs ruff (the venv's, from pyproject's [test] extra) and
# clang-format (apt), as scripts/setup.sh installs them.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
status=0
ruff check --no-fix . || status=1
mapfile -t cxx < <(bash scripts/cxx_sources.sh)
clang-format --dry-run -Werror "${cxx[@]}" || status=1
if [ "$status" != 0 ]; then
  echo "[lint] failed: scripts/format_all.sh fixes what can be fixed automatically" >&2
fi
exit "$status"
