"""Benchmark (issue 32): WLTC 3b through the IpmsmDrive FMU in plain fmpy at 10 ms, with either
`objective` (0 least current, 1 least loss). The vehicle is open loop here (the cycle's speed
imposed, the shaft torque from the default vehicle's inverse dynamics: mass, road load, gear,
wheel), so the loop is the FMU and fmpy's calls only: what the FMU costs per objective. Prints
the wall time of each run and its drive energies (DC, copper, iron, inverter).

    .venv/bin/python bench/bench_drive_objective.py [--cycle WLTC3b] [--until SECONDS] [--objective 0 1]
"""
from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from scenarios.vehicle.cycles import load_cycle
from scenarios.vehicle.longitudinal import VehicleParams

ROOT = Path(__file__).resolve().parents[1]
DT = 0.01  # s, the vehicle step


def shaft_torque_and_speed(cycle, v: VehicleParams):
    """Per vehicle step: the motor's shaft torque (N.m) and speed (rad/s) the cycle asks for."""
    t = np.arange(0.0, cycle.time_s[-1], DT)
    speed = np.interp(t, cycle.time_s, cycle.speed_mps)
    accel = np.gradient(speed, DT)
    force = v.mass * accel + np.where(speed > 0.01, v.road_load_A + v.road_load_B * speed
                                      + v.road_load_C * speed**2, 0.0)
    wheel_torque = force * v.wheel_radius
    T = wheel_torque / v.gear_ratio
    w_m = speed / v.wheel_radius * v.gear_ratio
    return t, T, w_m


def run(fmu_path: Path, objective: int, t, T, w_m) -> tuple[float, dict]:
    md = read_model_description(fmu_path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    tmp = Path(tempfile.mkdtemp())
    try:
        unzip = extract(fmu_path, unzipdir=tmp)
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="drive")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setInteger([vr["objective"]], [objective])
        fmu.exitInitializationMode()
        inputs = [vr["T_ref"], vr["w_m"]]
        outs = [vr[n] for n in ("E_dc", "E_cu", "E_fe", "E_inv")]
        t0 = time.perf_counter()
        for k in range(len(t)):
            fmu.setReal(inputs, [float(T[k]), float(w_m[k])])
            fmu.doStep(currentCommunicationPoint=float(t[k]), communicationStepSize=DT)
        wall = time.perf_counter() - t0
        E = dict(zip(("E_dc", "E_cu", "E_fe", "E_inv"), (x / 3600.0 for x in fmu.getReal(outs))))
        fmu.terminate()
        fmu.freeInstance()
        return wall, E
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycle", default="WLTC3b")
    ap.add_argument("--until", type=float, default=None)
    ap.add_argument("--objective", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--fmu", type=Path, default=ROOT / "build" / "fmu" / "IpmsmDrive.fmu")
    a = ap.parse_args()
    t, T, w_m = shaft_torque_and_speed(load_cycle(a.cycle), VehicleParams())
    if a.until is not None:
        keep = t < a.until
        t, T, w_m = t[keep], T[keep], w_m[keep]
    for objective in a.objective:
        wall, E = run(a.fmu, objective, t, T, w_m)
        print(f"{a.cycle} ({len(t)} steps of {DT * 1e3:.0f} ms), objective {objective}: {wall:.2f} s wall; "
              + ", ".join(f"{k} {v:.1f} Wh" for k, v in E.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
