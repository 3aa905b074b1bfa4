"""Benchmark (issue 14): a full WLTC 3b with the vehicle side at 10 ms through the IpmsmDrive FMU
in plain fmpy (one fmi2DoStep of 100 inner steps per vehicle step). Target: <= 15 s on a 2-core
machine. Prints the wall and CPU time of the run (the FMU's work and the Python vehicle side);
the optimum reference (an extra controller FMU call per vehicle step, for the copper-loss
comparison) is left out unless --reference.

    .venv/bin/python bench/bench_drive.py [--cycle WLTC3b] [--backend drive|native|fmpy] [--reference]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from scenarios.simulate import RunSpec, fmu_paths, simulate

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycle", default="WLTC3b")
    ap.add_argument("--backend", default="drive", choices=("drive", "native", "fmpy"))
    ap.add_argument("--reference", action="store_true")
    ap.add_argument("--build", type=Path, default=ROOT / "build")
    a = ap.parse_args(argv)
    cpu0 = time.process_time()
    spec = RunSpec(backend=a.backend, reference=a.reference)
    s = simulate(a.cycle, spec, fmus=fmu_paths(a.build), progress=False).to_dict()
    cpu = time.process_time() - cpu0
    print(f"{s['cycle']} on {s['backend']}: {s['wall_s']:.1f} s wall, {cpu:.1f} s CPU, "
          f"{s['steps']} inner steps ({1e6 * cpu / s['steps']:.2f} us CPU each), {s['Wh_per_km']:.2f} Wh/km, "
          f"torque RMSE {s['torque_rmse_Nm']:.4f} N.m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
