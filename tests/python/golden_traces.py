"""Golden traces: every output of the three FMUs over 2000 steps of a varied, deterministic input
sequence, reduced to one SHA-256 per output (of its float64 values' exact bytes), so that a
refactoring that must not change behaviour is checked bit for bit (test_golden_traces.py).

The sequence (inputs(k), k = 0..1999) steps the torque command through both signs and beyond
what the drive reaches at speed, ramps the speed up into field weakening and down through zero
to reverse, changes the DC-link voltage three times and heats magnet and winding (the winding
into the torque limit's derating). Each configuration (CONFIGS) runs it on one FMU, or on the
controller and the plant coupled by the drive's coupling description (Jacobi at h: the
controller sees the plant's currents at t_k, the plant applies the voltage the controller
computed over the previous step), so that the plant is fed the voltages a drive makes; every
controller method (1-3) and recursion (0-2), both CVODE methods and the thermal network are
covered.

The digests were recorded from the build of main at c0b1b5a (before issue 34's refactoring):
    python tests/python/golden_traces.py --write        # tests/data/golden_traces.json
Outputs added later are not in the record, and are not compared; a recorded output must stay.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

import fmi2_raw as raw

N_STEPS = 2000
RECORD = Path(__file__).resolve().parents[1] / "data" / "golden_traces.json"


def torque(k: int) -> float:
    """T_ref over the step from k, N.m: steps of either sign, some beyond the limits at speed."""
    for end, value in ((100, 0.0), (400, 150.0), (700, -120.0), (900, 250.0), (1200, -250.0), (1500, 80.0),
                       (1800, -40.0)):
        if k < end:
            return value
    return 0.0


def speed(k: int) -> float:
    """w_m, rad/s: up to 1100 (field weakening) by k = 1400, then down through zero to -300."""
    return 1100.0 * k / 1400.0 if k < 1400 else 1100.0 - 1400.0 * (k - 1400) / 600.0


def dc_voltage(k: int) -> float:
    return 355.0 if k < 500 else 300.0 if k < 1000 else 400.0 if k < 1500 else 330.0


def inputs(k: int) -> dict[str, float]:
    """The external inputs over the step from k (the drive's names)."""
    return {"T_ref": torque(k), "w_m": speed(k), "u_dc": dc_voltage(k),
            "T_magnet": 293.15 + 80.0 * k / N_STEPS,
            "T_winding": 293.15 + 130.0 * k / N_STEPS + (20.0 if k >= 1000 else 0.0),
            "T_coolant": 333.15, "T_ambient": 313.15}


PLANT_INPUTS = ("w_m", "u_dc", "T_magnet", "T_winding", "T_coolant", "T_ambient")
CONTROLLER_INPUTS = ("T_ref", "w_m", "u_dc", "T_magnet", "T_winding")
DRIVE_INPUTS = ("T_ref", "w_m", "u_dc", "T_magnet", "T_winding", "T_coolant", "T_ambient")

# name: (kind, parameters of the controller, parameters of the plant or the drive, step h)
CONFIGS = {
    "controller_m1_r0": ("controller", {"method": 1, "recursion": 0}, {}, 1e-4),
    "controller_m1_r1": ("controller", {"method": 1, "recursion": 1}, {}, 1e-4),
    "controller_m1_r2": ("controller", {"method": 1, "recursion": 2}, {}, 1e-4),
    "controller_m2": ("controller", {"method": 2}, {}, 1e-4),
    "controller_m3": ("controller", {"method": 3}, {}, 1e-4),
    "coupled_m1_r2": ("coupled", {"method": 1, "recursion": 2}, {}, 1e-4),
    "coupled_m1_r1_bdf": ("coupled", {"method": 1, "recursion": 1}, {"cvode_method": 2}, 1e-4),
    "coupled_m3_thermal": ("coupled", {"method": 3}, {"thermal_model": True, "R_s": 0.014}, 1e-4),
    "drive_m1_r2": ("drive", {}, {"method": 1, "recursion": 2}, 1e-3),
    "drive_m2_thermal": ("drive", {}, {"method": 2, "thermal_model": True, "T_magnet_estimate_error": 10.0},
                         1e-3),
    "drive_m1_r1_fast": ("drive", {}, {"method": 1, "recursion": 1, "sample_time": 2e-4, "I_max": 450.0}, 4e-4),
}


def _column(values) -> np.ndarray:
    return np.array([float(v) for v in values], dtype=np.float64)


def _digest(column: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(column, dtype="<f8").tobytes()).hexdigest()


class _Unit:
    """One instance, its outputs recorded after initialisation and after every step. `instance`
    makes it: fmi2_raw.Instance (FMI 2.0), or fmi3_raw.Instance3 (FMI 3.0, test_fmi3.py)."""

    def __init__(self, fmu: raw.Unzipped, tag: str, parameters: dict, instance=raw.Instance):
        self.inst = instance(fmu, tag)
        assert self.inst.setup() == raw.OK
        assert self.inst.enter() == raw.OK
        self.inst.set(**parameters)
        self.outputs = self.inst.names("output")
        self.rows: list[tuple] = []
        self.tag = tag

    def exit(self):
        status = self.inst.exit()
        assert status in (raw.OK, raw.WARNING), self.inst.log.text()
        self.record()

    def record(self):
        self.rows.append(tuple(self.inst.get(name) for name in self.outputs))

    def step(self, k: int, h: float):
        status = self.inst.step(h, k * h)
        assert status in (raw.OK, raw.WARNING), f"{self.tag} step {k}: {raw.STATUS[status]}\n{self.inst.log.text()}"

    def columns(self) -> dict[str, np.ndarray]:
        table = list(zip(*self.rows))
        return {f"{self.tag}.{name}": _column(table[j]) for j, name in enumerate(self.outputs)}


def run(config: str, fmus: dict[str, raw.Unzipped], instance=raw.Instance) -> dict[str, np.ndarray]:
    """Every output of the configuration's units, one value per communication point."""
    kind, controller_params, other_params, h = CONFIGS[config]
    if kind == "drive":
        drive = _Unit(fmus["IpmsmDrive"], "drive", other_params, instance)
        drive.inst.set(**{n: inputs(0)[n] for n in DRIVE_INPUTS})
        drive.exit()
        for k in range(N_STEPS):
            drive.inst.set(**{n: inputs(k)[n] for n in DRIVE_INPUTS})
            drive.step(k, h)
            drive.record()
        units = [drive]
    elif kind == "controller":
        # the measured currents follow the commands with a first-order lag of 0.3 per step
        ctl = _Unit(fmus["IpmsmController"], "controller", controller_params, instance)
        i_d = i_q = 0.0
        ctl.inst.set(**{n: inputs(0)[n] for n in CONTROLLER_INPUTS}, i_d=i_d, i_q=i_q)
        ctl.exit()
        for k in range(N_STEPS):
            i_d_ref, i_q_ref = ctl.inst.get("i_d_ref", "i_q_ref")
            i_d += 0.3 * (i_d_ref - i_d)
            i_q += 0.3 * (i_q_ref - i_q)
            ctl.inst.set(**{n: inputs(k)[n] for n in CONTROLLER_INPUTS}, i_d=i_d, i_q=i_q)
            ctl.step(k, h)
            ctl.record()
        units = [ctl]
    else:  # coupled by the drive's coupling description: the plant first
        plant = _Unit(fmus["IpmsmPlant"], "plant", other_params, instance)
        ctl = _Unit(fmus["IpmsmController"], "controller", controller_params, instance)
        plant.inst.set(**{n: inputs(0)[n] for n in PLANT_INPUTS})
        plant.exit()
        ctl.inst.set(**{n: inputs(0)[n] for n in CONTROLLER_INPUTS}, **dict(zip(("i_d", "i_q"), plant.inst.get(
            "i_d", "i_q"))))
        ctl.exit()
        for k in range(N_STEPS):
            i_d, i_q = plant.inst.get("i_d", "i_q")
            u_d, u_q = ctl.inst.get("u_d_ref", "u_q_ref")
            ctl.inst.set(**{n: inputs(k)[n] for n in CONTROLLER_INPUTS}, i_d=i_d, i_q=i_q)
            plant.inst.set(**{n: inputs(k)[n] for n in PLANT_INPUTS}, u_d=u_d, u_q=u_q)
            plant.step(k, h)
            ctl.step(k, h)
            plant.record()
            ctl.record()
        units = [plant, ctl]
    columns = {}
    for u in units:
        columns.update(u.columns())
        u.inst.free()
    return columns


def digests(fmu_dir: Path, configs=None) -> dict[str, dict[str, str]]:
    """{config: {unit.output: sha256 of its float64 values}} for the FMUs in fmu_dir."""
    with tempfile.TemporaryDirectory() as tmp:
        fmus = {name: raw.Unzipped(fmu_dir / f"{name}.fmu", Path(tmp) / name)
                for name in ("IpmsmController", "IpmsmPlant", "IpmsmDrive")}
        return {c: {name: _digest(col) for name, col in run(c, fmus).items()} for c in (configs or CONFIGS)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fmu-dir", type=Path, default=Path(__file__).resolve().parents[2] / "build" / "fmu")
    p.add_argument("--write", action="store_true", help=f"write the digests to {RECORD}")
    a = p.parse_args(argv)
    got = digests(a.fmu_dir)
    if a.write:
        RECORD.write_text(json.dumps({"n_steps": N_STEPS, "digests": got}, indent=1, sort_keys=True) + "\n")
        print(f"wrote {RECORD}: {sum(len(d) for d in got.values())} outputs in {len(got)} configurations")
        return 0
    want = json.loads(RECORD.read_text())["digests"]
    bad = [f"{c}: {n}" for c in want for n in want[c] if got.get(c, {}).get(n) != want[c][n]]
    print("\n".join(bad) if bad else f"all {sum(len(d) for d in want.values())} recorded outputs bit for bit")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
