#!/usr/bin/env bash
# The main job: set up (system packages, Python venv, build), then the controller's torque-speed
# sweep: out/sweep/{sweep.csv,summary.json,current_trajectories.png}. Idempotent.
set -euo pipefail
cd "$(dirname "$0")"
source scripts/setup.sh
python -m scenarios sweep --out out/sweep "$@"
