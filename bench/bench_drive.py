"""Benchmark (issue 14): a full WLTC 3b with the vehicle side at 10 ms through the IpmsmDrive FMU
in plain fmpy (one fmi2DoStep of 100 inner steps per vehicle step). Target: <= 15 s on a 2-core
machine. Prints the wall and CPU time of the run; with --split, a second, instrumented run gives
their split: the time inside fmi2DoStep (the FMU's work) and the rest, the Python side (the vehicle
models, the accounts and the fmpy calls around the steps; it also carries the split's own clock
readings, about 1.5 us a vehicle step, which is why the headline figure comes from a run without
them). The optimum
reference (an extra controller FMU call per vehicle step, for the copper-loss comparison) is left
out unless --reference.

    .venv/bin/python bench/bench_drive.py [--cycle WLTC3b] [--until SECONDS] [--backend drive|reference]
                                          [--reference] [--split]

With --backend reference (the reference loop) the split counts both FMUs' steps.
"""
from __future__ import annotations

import argparse
import functools
import time
from contextlib import contextmanager
from pathlib import Path

from scenarios.cosim import BACKEND_ALIASES, BACKENDS
from scenarios.cosim.fmu import Fmu
from scenarios.runs.simulate import RunSpec, fmu_paths, simulate
from scenarios.vehicle.cycles import load_cycle, segment

ROOT = Path(__file__).resolve().parents[1]


class _TimedDll:
    """An FMU's loaded binary whose fmi2DoStep adds its wall and CPU time to `spent`."""

    def __init__(self, dll, spent: dict):
        self._dll, self._spent = dll, spent

    def __getattr__(self, name):
        f = getattr(self._dll, name)
        if name != "fmi2DoStep":
            return f
        spent, wall, cpu = self._spent, time.perf_counter, time.process_time

        def timed(*args):
            w0, c0 = wall(), cpu()
            try:
                return f(*args)
            finally:
                spent["cpu"] += cpu() - c0
                spent["wall"] += wall() - w0
        return timed


@contextmanager
def do_step_clock():
    """Accumulates the wall and CPU time spent inside every fmi2DoStep call of the FMUs opened
    in the block (scenarios.cosim.fmu.Fmu): yields a dict with "wall" and "cpu" seconds. The
    timing wrapper's own Python call is counted on the Python side."""
    spent = {"wall": 0.0, "cpu": 0.0}
    init = Fmu.__init__

    @functools.wraps(init)
    def timed_init(self, *args, **kwargs):
        init(self, *args, **kwargs)
        self.dll = _TimedDll(self.dll, spent)

    Fmu.__init__ = timed_init
    try:
        yield spent
    finally:
        Fmu.__init__ = init


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycle", default="WLTC3b")
    ap.add_argument("--until", type=float, default=None, help="run only the cycle's first SECONDS")
    ap.add_argument("--backend", default="drive", choices=BACKENDS + tuple(BACKEND_ALIASES))
    ap.add_argument("--reference", action="store_true")
    ap.add_argument("--split", action="store_true", help="add an instrumented run: time inside fmi2DoStep vs the rest")
    ap.add_argument("--build", type=Path, default=ROOT / "build")
    a = ap.parse_args(argv)
    spec = RunSpec(backend=a.backend, reference=a.reference)
    cycle = load_cycle(a.cycle)
    if a.until is not None:
        cycle = segment(cycle, cycle.time_s[0], cycle.time_s[0] + a.until)

    def timed_run():
        """The summary and the (wall, CPU) seconds of the whole simulate() call: the run's loop
        (the summary's wall_s) and its set-up (loading the FMUs)."""
        wall0, cpu0 = time.perf_counter(), time.process_time()
        s = simulate(cycle, spec, fmus=fmu_paths(a.build), progress=False).to_dict()
        return s, time.perf_counter() - wall0, time.process_time() - cpu0

    s, wall, cpu = timed_run()
    print(f"{s['cycle']} on {s['backend']}: {s['wall_s']:.1f} s wall (the run's loop), {cpu:.1f} s CPU, "
          f"{s['steps']} inner steps ({1e6 * cpu / s['steps']:.2f} us CPU each), {s['Wh_per_km']:.2f} Wh/km, "
          f"torque RMSE {s['torque_rmse_Nm']:.4f} N.m")
    if not a.split:
        return 0
    with do_step_clock() as in_do_step:
        s, wall, cpu = timed_run()
    n = s["vehicle_steps"]
    py_wall, py_cpu = wall - in_do_step["wall"], cpu - in_do_step["cpu"]
    print(f"  split of an instrumented run's simulate() ({wall:.2f} s wall with set-up, {cpu:.2f} s CPU): "
          f"inside fmi2DoStep {in_do_step['wall']:.2f} s wall, {in_do_step['cpu']:.2f} s CPU; "
          f"the Python side (the rest) {py_wall:.2f} s wall, {py_cpu:.2f} s CPU "
          f"({1e6 * py_cpu / n:.1f} us CPU per vehicle step)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
