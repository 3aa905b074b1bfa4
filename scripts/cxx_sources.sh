#!/usr/bin/env bash
# The project's C and C++ sources, one per line (NUL-free paths): what scripts/lint.sh checks and
# scripts/format_all.sh formats. Build trees, the venv and outputs are not sources.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
find . \( -path ./.git -o -path ./.venv -o -path './build*' -o -path ./out \) -prune -o \
  -type f \( -name '*.cpp' -o -name '*.hpp' -o -name '*.h' -o -name '*.c' \) -print | sed 's|^\./||' | sort
