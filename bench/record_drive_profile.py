"""The drive's inputs over a drive cycle, recorded for bench_drive_model (the C++-only measurement
of IpmsmDrive): T_ref, w_m, u_dc of every vehicle step (10 ms), from a run of the scenarios with
the IpmsmDrive backend (the vehicle side's response to the drive, so a realistic sequence).

    .venv/bin/python bench/record_drive_profile.py [--cycle WLTC3b] [--out build/wltc3b_profile.csv]
"""
from __future__ import annotations

import argparse
import csv
import tempfile
from pathlib import Path

from scenarios.runs.simulate import RunSpec, fmu_paths, simulate

ROOT = Path(__file__).resolve().parents[1]
VEHICLE_STEP = 0.01  # s: RunSpec's default dt, one IpmsmDrive fmi2DoStep


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycle", default="WLTC3b")
    ap.add_argument("--build", type=Path, default=ROOT / "build")
    ap.add_argument("--out", type=Path, default=ROOT / "build" / "wltc3b_profile.csv")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="ipmsm-profile-") as tmp:
        spec = RunSpec(backend="drive", reference=False, trace_dt=VEHICLE_STEP)
        simulate(a.cycle, spec, fmus=fmu_paths(a.build), out=Path(tmp), progress=False)
        with open(Path(tmp) / "trace.csv") as f, open(a.out, "w") as out:
            out.write(f"# {a.cycle}, one row per vehicle step of {VEHICLE_STEP} s: the drive's inputs\n")
            out.write("T_ref,w_m,u_dc\n")
            for r in csv.DictReader(f):
                out.write(f"{r['T_ref_Nm']},{r['w_m_rad_s']},{r['u_dc_V']}\n")
    print(a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
