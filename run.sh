#!/usr/bin/env bash
# The main job: set up (system packages, Python venv, build), then
#   1. the controller's torque-speed sweep: out/sweep/{sweep.csv,summary.json,current_trajectories.png}
#   2. the Ferrari-versus-2-D-table study on WLTC 3b (least current's 4 variants and least loss's 3 x 5
#      conditions, the FMUs coupled at 100 us with the vehicle, driver and battery):
#      out/compare/{report.md,summary.csv,study.png,runs/}
# Idempotent. Extra arguments go to the study (e.g. --cycles WLTC3b UDDS HWFET).
set -euo pipefail
cd "$(dirname "$0")"
study_args=("$@")
set --  # the sourced set-up must not see the study's arguments
source scripts/setup.sh
python -m scenarios sweep --out out/sweep
python -m scenarios compare --out out/compare "${study_args[@]}"
