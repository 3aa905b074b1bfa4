#!/bin/bash
# The controller benchmark of two revisions side by side: bench_controller built from each with
# the project's Release flags (C++17, -O3 -DNDEBUG, the core as PIC), run alternately ROUNDS times
# each (this VM drifts by 5-10 % between quiet and busy phases: alternating spreads that over
# both); prints each row's best, in ns per call. A revision may be "work" (the working tree).
# Rows are matched by name; a row one revision lacks shows "-".
#
# Usage: bench/ab.sh REV_A REV_B [ROUNDS [BENCH_ARGUMENTS...]]     e.g. bench/ab.sh fcaaf63 HEAD 3
# BENCH_ARGUMENTS go to both bench_controllers, e.g. the corpus rows alone:
#   bench/ab.sh main HEAD 3 --corpus-only $(python tests/python/map_corpus.py /tmp/corpus)
set -euo pipefail
[ $# -ge 2 ] || { sed -n '2,11p' "$0"; exit 2; }
repo=$(cd "$(dirname "$0")/.." && pwd)
rounds=${3:-3}
bench_args=("${@:4}")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# The FMI-free sources: fmu_src/core/ before ed0f875 (included as "quartic.hpp"), then
# fmu_src/{numerics,machine,control}/ (included as "numerics/quartic.hpp").
build() {  # build REV DIR
    local rev=$1 d=$2
    mkdir -p "$d/src" "$d/obj"
    # tests/support: the generated flux maps bench_controller includes (where the revision has them)
    if [ "$rev" = work ]; then
        cp -r "$repo/fmu_src" "$repo/bench" "$d/src/"
        mkdir -p "$d/src/tests" && cp -r "$repo/tests/support" "$d/src/tests/" 2>/dev/null || true
    else
        git -C "$repo" archive "$rev" fmu_src bench | tar -x -C "$d/src"
        git -C "$repo" archive "$rev" tests/support 2>/dev/null | tar -x -C "$d/src" 2>/dev/null || true
    fi
    local include sources=()
    if [ -d "$d/src/fmu_src/core" ]; then
        include="$d/src/fmu_src/core"
        sources=("$d"/src/fmu_src/core/*.cpp)
    else
        include="$d/src/fmu_src"
        sources=("$d"/src/fmu_src/{numerics,machine,control}/*.cpp)
    fi
    [ -d "$d/src/tests/support" ] && sources+=("$d"/src/tests/support/*.cpp)
    local flags=(-std=c++17 -O3 -DNDEBUG -DIPMSM_SOURCE_DIR="\"$repo\"" -I"$include" -I"$d/src/tests/support" -isystem /usr/include/eigen3)
    for f in "${sources[@]}"; do g++ "${flags[@]}" -fPIC -c "$f" -o "$d/obj/$(basename "$f" .cpp).o" & done
    wait
    ar rcs "$d/libcore.a" "$d"/obj/*.o
    g++ "${flags[@]}" -fPIE "$d/src/bench/bench_controller.cpp" "$d/libcore.a" \
        -o "$d/bench_controller"
}

echo "building $1 and $2 ..." >&2
build "$1" "$tmp/a"
build "$2" "$tmp/b"
for ((k = 1; k <= rounds; ++k)); do
    echo "round $k of $rounds ..." >&2
    "$tmp/a/bench_controller" "${bench_args[@]}" | sed 's/^/a|/' >> "$tmp/out"
    "$tmp/b/bench_controller" "${bench_args[@]}" | sed 's/^/b|/' >> "$tmp/out"
done
# Rows are "name  value ns  note".
awk -v A="$1" -v B="$2" '
    match($0, / +[0-9.]+ ns/) {
        v = substr($0, 1, 1); name = substr($0, 3, RSTART - 3); x = substr($0, RSTART, RLENGTH) + 0
        if (!(name in seen)) { seen[name] = 1; order[++n] = name }
        key = v SUBSEP name
        if (!(key in best) || x < best[key]) best[key] = x
    }
    END {
        printf "%-72s %10s %10s\n", "ns per call, best of each", A, B
        for (i = 1; i <= n; ++i) {
            a = ("a" SUBSEP order[i]) in best ? sprintf("%.1f", best["a" SUBSEP order[i]]) : "-"
            b = ("b" SUBSEP order[i]) in best ? sprintf("%.1f", best["b" SUBSEP order[i]]) : "-"
            printf "%-72s %10s %10s\n", order[i], a, b
        }
    }' "$tmp/out"
