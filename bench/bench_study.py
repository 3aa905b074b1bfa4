"""Benchmark (issue 18): what running on dask.distributed costs and gains. A script, not a
timed test; the figures depend on the machine and its load.

    .venv/bin/python bench/bench_study.py overhead [--runs 40]
        the scheduler's cost per run: N short runs (2 s of WLTC 3b) directly in this process,
        one after the other, against the same runs as a study on a LocalCluster of one worker;
        (study wall - cluster start - direct wall) / N.
    .venv/bin/python bench/bench_study.py five-cycle [--window-s 60 | --full] [--workers 1 2]
        the five-cycle compare study (5 cycles x 4 conditions x 4 variants = 80 runs) on 1 and 2
        workers: wall time and speed-up. By default each run drives only the first --window-s
        seconds of its cycle, and the whole study's time is extrapolated by simulated seconds
        (the cost of a run is a start-up plus a cost per simulated second, both measured);
        --full runs the whole cycles. Then what 32 workers would take by that measurement.
    .venv/bin/python bench/bench_study.py memory [--runs 1000]
        a study of N runs of 2 s windows on the local cluster: the resident memory of this
        process (client and scheduler) and of the workers, sampled every second.
"""
from __future__ import annotations

import argparse
import heapq
import statistics
import tempfile
import threading
import time
from dataclasses import replace
from pathlib import Path

import psutil

from scenarios.runs.simulate import STUDY_CONDITIONS, simulate
from scenarios.study import run_study
from scenarios.study.compare import VARIANTS, study_runs
from scenarios.study.plan import run_cycle
from scenarios.study.spec import Run, run_spec
from scenarios.vehicle.cycles import STANDARD_CYCLES, load_cycle

ROOT = Path(__file__).resolve().parents[1]
SHORT = (300.0, 302.0)  # s of WLTC 3b: the vehicle moving


def short_runs(n: int) -> list[Run]:
    """n distinct runs of 2 s of WLTC 3b (conditions varied to make them distinct)."""
    methods = (("ferrari", 1), ("ferrari", 2), ("lut_speed", 2), ("lut_flux", 2))
    out = []
    for i in range(n):
        m, r = methods[i % 4]
        out.append(Run(cycle="WLTC3b", window_start_s=SHORT[0], window_end_s=SHORT[1], method=m, recursion=r,
                       u_dc_scale=round(1.0 - 0.001 * (i // 4), 6)))
    return out


def direct(runs: list[Run]) -> float:
    t0 = time.perf_counter()
    cycles = {}
    for run in runs:
        simulate(run_cycle(run, cycles), run_spec(run), progress=False)
    return time.perf_counter() - t0


def study_wall(runs: list[Run], workers: int, out: Path | None = None) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        res = run_study(runs, out or Path(tmp), workers=workers, progress=False)
        wall = time.perf_counter() - t0
    assert res.failed == 0, f"{res.failed} runs failed"
    return wall


def overhead(a) -> None:
    runs = short_runs(a.runs)
    t_direct_1 = direct(runs[:1])
    t_direct = direct(runs)
    t_start = study_wall(runs[:1], 1) - t_direct_1       # cluster start and stop, one run's overhead
    t_study = study_wall(runs, 1)
    per_run = (t_study - t_start - t_direct) / len(runs)
    print(f"overhead: {len(runs)} runs of 2 s: direct {t_direct:.2f} s ({t_direct / len(runs) * 1e3:.0f} ms a run); "
          f"study on 1 worker {t_study:.2f} s, of which cluster start/stop {t_start:.2f} s; "
          f"scheduler overhead {per_run * 1e3:.0f} ms a run")


def lpt_makespan(durations: list[float], workers: int) -> float:
    """Longest-processing-time-first schedule on `workers` identical workers."""
    heap = [0.0] * workers
    for d in sorted(durations, reverse=True):
        heapq.heapreplace(heap, heap[0] + d)
    return max(heap)


def five_cycle(a) -> None:
    cycles = tuple(STANDARD_CYCLES)
    full_s = {c: load_cycle(c).duration_s for c in cycles}
    jobs = [run for run, _ in study_runs(cycles, STUDY_CONDITIONS, VARIANTS)]
    if not a.full:
        jobs = [replace(r, window_start_s=0.0, window_end_s=a.window_s) for r in jobs]
    print(f"five-cycle: {len(jobs)} runs, " + ("whole cycles" if a.full else f"the first {a.window_s:g} s of each"))
    walls, rows_by_workers = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for w in a.workers:
            out = Path(tmp) / f"w{w}"
            t0 = time.perf_counter()
            res = run_study(jobs, out, workers=w, progress=False)
            walls[w] = time.perf_counter() - t0
            rows = rows_by_workers[w] = res.table.to_pylist()
            run_wall = sum(r["run_wall_s"] for r in rows)
            print(f"  {w} worker(s): {walls[w]:.1f} s wall, {run_wall:.1f} s of runs on the workers, "
                  f"speed-up {walls[min(walls)] / walls[w]:.2f} over {min(walls)} worker(s)")
    # the runs' own times from the fewest workers: the least contention for the machine's cores
    rows = rows_by_workers[min(walls)]
    if a.full:
        per_run = [r["run_wall_s"] for r in rows]
    else:
        # cost of a run = start-up + rate x simulated seconds: start-up from 2-s runs, rate from these
        short = statistics.median(r["run_wall_s"] for r in run_study_rows(short_runs(8), min(walls)))
        rate = statistics.median((r["run_wall_s"] - short) / (a.window_s - 2.0) for r in rows)
        per_run = [short + rate * (full_s[Path(r.cycle).name] - 2.0) for r in jobs]
        print(f"  a run costs {short:.2f} s + {rate * 1e3:.1f} ms per simulated second (on {min(walls)} "
              f"worker(s)): the whole study {sum(per_run) / 60:.1f} CPU-min")
        for w in a.workers:
            print(f"  whole cycles, {w} worker(s) (extrapolated): {lpt_makespan(per_run, w) / 60:.1f} min")
    for w in (32,):
        print(f"  {w} workers (by this measurement, LPT schedule of the runs' times): "
              f"{lpt_makespan(per_run, w) / 60:.1f} min; the longest run alone {max(per_run) / 60:.1f} min")


def run_study_rows(runs: list[Run], workers: int) -> list[dict]:
    with tempfile.TemporaryDirectory() as tmp:
        return run_study(runs, Path(tmp), workers=workers, progress=False).table.to_pylist()


def memory(a) -> None:
    runs = short_runs(a.runs)
    me = psutil.Process()
    samples = []  # (t, client+scheduler RSS, workers' RSS) in MB
    stop = threading.Event()

    def sample():
        while not stop.is_set():
            kids = me.children(recursive=True)
            rss = 0
            for k in kids:
                try:
                    rss += k.memory_info().rss
                except psutil.Error:
                    pass
            samples.append((time.perf_counter(), me.memory_info().rss / 2**20, rss / 2**20))
            stop.wait(1.0)

    th = threading.Thread(target=sample, daemon=True)
    th.start()
    t0 = time.perf_counter()
    wall = study_wall(runs, a.workers)
    stop.set()
    th.join()
    print(f"memory: {len(runs)} runs of 2 s on {a.workers} workers in {wall:.0f} s "
          f"({wall / len(runs) * 1e3:.0f} ms a run); resident memory (MB) over the study:")
    print("  time (s)              " + " ".join(f"{s[0] - t0:6.0f}" for s in _spread(samples)))
    print("  client + scheduler    " + " ".join(f"{s[1]:6.0f}" for s in _spread(samples)))
    print("  workers (all)         " + " ".join(f"{s[2]:6.0f}" for s in _spread(samples)))
    print("  (the last column: after the cluster closed and runs.parquet was consolidated)")


def _spread(samples: list, n: int = 9) -> list:
    """n samples evenly over the list, its first (after start-up) and last included."""
    idx = sorted({min(len(samples) - 1, round(i * (len(samples) - 1) / (n - 1))) for i in range(n)})
    return [samples[i] for i in idx]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    o = sub.add_parser("overhead")
    o.add_argument("--runs", type=int, default=40)
    f = sub.add_parser("five-cycle")
    f.add_argument("--window-s", type=float, default=60.0)
    f.add_argument("--full", action="store_true")
    f.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    m = sub.add_parser("memory")
    m.add_argument("--runs", type=int, default=1000)
    m.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    {"overhead": overhead, "five-cycle": five_cycle, "memory": memory}[a.what](a)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
