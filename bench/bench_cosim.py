"""Benchmark of the drive at 100 us on a drive-like profile, advanced in 10 ms chunks (as the
vehicle side calls it): the IpmsmDrive FMU (the fast path) and the reference loop (IpmsmController +
IpmsmPlant coupled in Python, scenarios/cosim/reference.py).

    python -m bench.bench_cosim --seconds 60            # drive 60 s, reference loop 10 s
    python -m bench.bench_cosim --seconds 1800          # measures a WLTC-length run
    python -m bench.bench_cosim --seconds 60 --fmpy-seconds 60 --json out.json

The profile (scaled to the run's length): speed 0 -> 12 000 r/min over the first 40 %, held
over 20 %, back to 0 over the last 40 %; torque cycling every 10 s through steps and ramps
(+150 N.m, ramp to +50, -80 N.m regenerating, ramp to +220, 0), clamped by the controller to
what the limits allow; u_dc sagging with power around 355 V; magnet 60 -> 90 degC, winding
70 -> 110 degC. Prints wall and CPU seconds, us per coupled step, the real-time factor and the
1800 s WLTC estimate (18 million steps at the measured cost per step). --profile stress: a new
random torque command every 10 ms instead (a bound, far harsher than a driver).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

from scenarios.cosim.drive_fmu import DriveFmu
from scenarios.cosim.reference import ReferenceDrive

ROOT = Path(__file__).resolve().parents[1]
H = 1e-4
CHUNK = 100  # 10 ms
WLTC_S = 1800.0
RPM = 2 * math.pi / 60


def torque_pattern(t: float) -> float:
    """N.m: a 10-s pattern of steps and ramps."""
    x = t % 10.0
    if x < 2.0:
        return 150.0
    if x < 4.0:
        return 150.0 - 50.0 * (x - 2.0)       # ramp down to 50
    if x < 6.0:
        return -80.0                          # regenerating
    if x < 8.0:
        return -80.0 + 150.0 * (x - 6.0)      # ramp up to 220
    return 0.0


def stress_torque(t: float) -> float:
    """N.m: a new pseudo-random torque in [-250, 250] every 10 ms chunk (far harsher than a
    driver: the currents are in transient most of the time)."""
    j = int(round(t / (CHUNK * H)))
    x = (j * 2654435761 + 12345) % 4294967296 / 4294967296.0
    return -250.0 + 500.0 * x


def profile(t: float, duration: float, kind: str = "drive") -> tuple[float, float, float, float, float]:
    """(T_ref, w_m, u_dc, T_magnet, T_winding) at t of a run of `duration` seconds."""
    x = t / duration
    top = 12000 * RPM
    w_m = top * min(1.0, x / 0.4, (1.0 - x) / 0.4)
    w_m = max(w_m, 0.0)
    T_ref = torque_pattern(t) if kind == "drive" else stress_torque(t)
    u_dc = 355.0 - 2.5e-4 * T_ref * w_m  # sags ~25 V at 100 kW
    return T_ref, w_m, u_dc, 273.15 + 60.0 + 30.0 * x, 273.15 + 70.0 + 40.0 * x


def run(backend: str, seconds: float, fmu_dir: Path, progress: bool = False, kind: str = "drive") -> dict:
    n_chunks = int(round(seconds / (CHUNK * H)))
    T_ref, w_m, u_dc, T_mag, T_win = profile(0.0, seconds, kind)
    start = dict(w_m=w_m, u_dc=u_dc, T_magnet=T_mag, T_winding=T_win, T_ref=T_ref)
    energy = 0.0
    with (DriveFmu(fmu_dir / "IpmsmDrive.fmu", **start) if backend == "drive" else
          ReferenceDrive(fmu_dir / "IpmsmController.fmu", fmu_dir / "IpmsmPlant.fmu", **start)) as drive:
        wall0, cpu0 = time.perf_counter(), time.process_time()
        for j in range(n_chunks):
            T_ref, w_m, u_dc, T_mag, T_win = profile(j * CHUNK * H, seconds, kind)
            r = drive.advance(CHUNK * H, T_ref, w_m, u_dc, T_mag, T_win)
            energy += r.P_elec * CHUNK * H
            if progress and j % 1000 == 999:
                el = time.perf_counter() - wall0
                print(f"  {backend}: {(j + 1) * CHUNK * H:.0f} s simulated, {el:.1f} s wall", flush=True)
        wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
        steps = n_chunks * CHUNK
    return {"backend": backend, "profile": kind, "simulated_s": steps * H, "steps": steps, "wall_s": wall, "cpu_s": cpu,
            "us_per_step_wall": wall / steps * 1e6, "us_per_step_cpu": cpu / steps * 1e6,
            "real_time_factor": steps * H / wall, "wltc_1800s_estimate_s": wall / steps * WLTC_S / H,
            "wltc_1800s_estimate_cpu_s": cpu / steps * WLTC_S / H, "E_elec_kWh": energy / 3.6e6}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.bench_cosim", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=60.0, help="simulated seconds, the drive FMU")
    ap.add_argument("--fmpy-seconds", type=float, default=None,
                    help="simulated seconds, the reference loop (default min(seconds, 10); 0: skip)")
    ap.add_argument("--fmu-dir", type=Path, default=Path(os.environ.get("IPMSM_FMU_DIR", ROOT / "build" / "fmu")))
    ap.add_argument("--json", type=Path, default=None, help="write the results here")
    ap.add_argument("--profile", choices=("drive", "stress"), default="drive",
                    help="drive: the profile above; stress: a new random torque in [-250, 250] N.m every 10 ms")
    ap.add_argument("--progress", action="store_true")
    args = ap.parse_args(argv)
    fmpy_s = min(args.seconds, 10.0) if args.fmpy_seconds is None else args.fmpy_seconds
    print(f"the drive at h = 100 us, 10 ms chunks; {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"FMUs {args.fmu_dir}; profile {args.profile}")
    results = []
    runs = [("drive", args.seconds)]
    if fmpy_s > 0:
        runs.append(("fmpy", fmpy_s))
        if fmpy_s != args.seconds:
            runs.append(("drive", fmpy_s))  # the same (shorter) profile, for a direct comparison
    for backend, seconds in runs:
        r = run(backend, seconds, args.fmu_dir, args.progress, args.profile)
        results.append(r)
    print()
    print(f"{'backend':8} {'sim s':>7} {'steps':>9} {'wall s':>8} {'CPU s':>8} {'us/step':>8} {'CPU us/step':>11} "
          f"{'RT factor':>9} {'WLTC 1800 s: wall':>17} {'CPU':>7}")
    for r in results:
        print(f"{r['backend']:8} {r['simulated_s']:7.1f} {r['steps']:9d} {r['wall_s']:8.2f} {r['cpu_s']:8.2f} "
              f"{r['us_per_step_wall']:8.2f} {r['us_per_step_cpu']:11.2f} {r['real_time_factor']:9.1f} "
              f"{r['wltc_1800s_estimate_s']:15.0f} s {r['wltc_1800s_estimate_cpu_s']:5.0f} s")
    print(f"\n(target: 1800 s WLTC in <= 60 s wall, i.e. <= {60.0 / (WLTC_S / H) * 1e6:.2f} us per coupled step; "
          "the estimate is 18 million steps at the measured cost per step of this profile)")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
