"""The seed's question on a real drive: online Ferrari control (the paper's recursion and the
exact optimum on the flux map) against the industry's 2-D lookup tables (over torque x speed,
and over torque x V_max/omega), over drive cycles and over conditions the tables were not made
for (a sagging DC link, hot and cold magnets). Writes report.md, summary.csv/json and plots.

A preset of `python -m scenarios study` (scenarios.study): its runs execute there (a local
dask cluster or --scheduler's), land in runs.parquet and are skipped when run again.
"""
from __future__ import annotations

import csv
import re
import subprocess
import textwrap
from dataclasses import dataclass
from pathlib import Path

from scenarios.core.boundary import strict_json, write_atomically
from scenarios.core.constants import T_REFERENCE_K, U_DC_NOMINAL_V, ZERO_CELSIUS_K
from scenarios.core.paths import BUILD_DIR
from scenarios.runs.results import RunSummary
from scenarios.runs.simulate import STUDY_CONDITIONS
from scenarios.study import run_study as study
from scenarios.study import table
from scenarios.study.spec import Run


@dataclass(frozen=True)
class Variant:
    label: str
    method: str
    recursion: int
    objective: str = "current"   # what the command minimises (scenarios.drives.description.OBJECTIVES)


VARIANTS = (
    Variant("Ferrari, recursion 1 (paper)", "ferrari", 1),
    Variant("Ferrari, recursion 2 (exact)", "ferrari", 2),
    Variant("2-D table, torque x speed", "lut_speed", 2),
    Variant("2-D table, torque x V_max/w", "lut_flux", 2),
)
#: least loss (docs/least_loss.md): Ferrari's online least loss, and the 2-D tables made for least
#: loss at the tables' u_dc and magnet temperature (as SyR-e's maximum-efficiency maps are made)
LEAST_LOSS_VARIANTS = (
    Variant("Ferrari, least loss", "ferrari", 2, "loss"),
    Variant("2-D table least loss, torque x speed", "lut_speed", 2, "loss"),
    Variant("2-D table least loss, torque x V_max/w", "lut_flux", 2, "loss"),
)


def default_variants() -> tuple[Variant, ...]:
    """The study's variants: the least-loss ones too where the FMUs have the least-loss controller."""
    from scenarios.drives.description import controller_has_objective
    return VARIANTS + (LEAST_LOSS_VARIANTS if controller_has_objective() else ())


def _slug(s: str) -> str:
    s = re.sub(r"(?<![A-Za-z0-9])-(?=[0-9])", "minus ", s)  # "-20 degC" and "20 degC" stay apart
    return re.sub(r"[^A-Za-z0-9]+", "_", s).strip("_").lower()


@dataclass(frozen=True)
class StudyRun:
    """One run of the study: its variant's label, its folder (relative to the study's) and summary."""

    variant: str
    run_dir: str
    summary: RunSummary

    @property
    def condition(self) -> str:
        return self.summary.conditions["name"]

    def to_dict(self) -> dict:
        return {**self.summary.to_dict(), "variant": self.variant, "run_dir": self.run_dir}


def controller_costs(build: Path) -> dict:
    """ns per call of each method, from the C++ benchmark (build/bin/bench_controller)."""
    exe = build / "bin" / "bench_controller"
    if not exe.exists():
        return {}
    text = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    def ns(pattern):
        m = re.search(pattern + r"\s+([0-9.]+) ns", text)
        return float(m.group(1)) if m else None
    return {
        "Ferrari, recursion 1 (paper)": ns(r"recursion 1, default map, trajectory"),
        "Ferrari, recursion 2 (exact)": ns(r"recursion 2, default map, trajectory"),
        "2-D table, torque x speed": ns(r"torque x speed \([0-9]+ bytes\), random"),
        "2-D table, torque x V_max/w": ns(r"torque x V_max/omega \([0-9]+ bytes\), random"),
    }


def study_runs(cycles=("WLTC3b",), conditions=STUDY_CONDITIONS, variants=None,
               drive: Path | None = None) -> list[tuple[Run, Variant]]:
    """The compare study as study runs: every variant (None: default_variants()) at every
    condition on every cycle."""
    variants = default_variants() if variants is None else variants
    d = str(Path(drive).resolve()) if drive else ""
    # each method's own commands (command_check 0: a failing command is counted, not replaced), so
    # that the study compares the methods, not the controller's safety net (docs/controller.md)
    return [(Run.of_conditions(k, drive=d, cycle=c, method=v.method, recursion=v.recursion, command_check=0,
                               objective=v.objective), v)
            for c in cycles for k in conditions for v in variants]


def run_study(out: Path, cycles=("WLTC3b",), conditions=STUDY_CONDITIONS, variants=None,
              build: Path = BUILD_DIR, workers: int | None = None, scheduler: str | None = None,
              drive: Path | None = None) -> list[StudyRun]:
    """The compare study, run as a study (scenarios.study: out/runs.parquet, traces/, resumable),
    then reported as before: report.md, summary.csv/json, study.png and runs/<run>/ (summary.json,
    trace.csv, run.png)."""
    jobs = study_runs(cycles, conditions, variants, drive)
    print(f"compare: {len(jobs)} runs -> {out}", flush=True)
    res = study([r for r, _ in jobs], out, scheduler=scheduler, workers=workers, build=build)
    rows = {r["key"]: r for r in res.table.to_pylist()}
    failed = [(run, rows[key]["error"]) for key, (run, _) in zip(res.keys, jobs) if rows[key]["status"] != "ok"]
    if failed:
        raise RuntimeError(f"compare: {len(failed)} runs failed, the first: {failed[0][0]}: {failed[0][1]}")
    results = []
    for key, (run, v) in zip(res.keys, jobs):
        s = table.summary_of(rows[key])
        run_dir = out / "runs" / f"{_slug(run.cycle)}__{_slug(s.conditions['name'])}__{_slug(v.label)}"
        run_dir.mkdir(parents=True, exist_ok=True)
        write_atomically(run_dir / "summary.json", s.to_json())
        table.write_trace_csv(table.trace_path(out, key), run_dir / "trace.csv")
        results.append(StudyRun(v.label, str(run_dir.relative_to(out)), s))
    costs = controller_costs(build)
    from scenarios.drives.description import load_drive
    write_report(out, results, costs, load_drive(drive))
    return results


def _memory(s: RunSummary) -> str:
    if s.method == "ferrari":
        # Online Ferrari needs the flux map (51 x 71 points, psi_d and psi_q) for any u_dc and T_magnet.
        return "flux map 58 kB (any u_dc, T)"
    per = 29561  # bytes of one 41 x 41 table pair (reported by the FMU as table_bytes)
    return f"{per / 1000:.0f} kB per table" + (" per u_dc and T" if s.method == "lut_speed" else " per T")


def _copper_excess(s: RunSummary) -> float:
    """The run's copper loss over the optimum's, less 1 (NaN without the optimum)."""
    if not s.copper_loss_optimal_Wh:
        return float("nan")
    return s.copper_loss_Wh / s.copper_loss_optimal_Wh - 1


def loss_excess(s: RunSummary) -> float:
    """The run's drive loss (copper + iron + inverter) over the least-loss optimum's at the same
    delivered shaft torque and conditions, less 1 (NaN without that optimum)."""
    if not s.drive_loss_optimal_Wh:
        return float("nan")
    return s.drive_loss_Wh / s.drive_loss_optimal_Wh - 1


def _pct(x: float) -> str:
    return "–" if x != x else f"{x:+.2%}"


def write_report(out: Path, results: list[StudyRun], costs: dict, drive=None) -> None:
    keys = ("cycle", "conditions", "variant", "Wh_per_km", "energy_battery_Wh", "distance_km", "speed_rmse_mps",
            "torque_rmse_Nm", "torque_error_max_Nm", "copper_loss_Wh", "copper_loss_optimal_Wh",
            "current_excess_rms_A", "iron_loss_Wh", "inverter_loss_Wh", "drive_loss_Wh", "drive_loss_optimal_Wh",
            "objective", "wall_s", "run_dir")
    def write_csv(tmp: Path) -> None:
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(keys)
            for r in results:
                d = r.to_dict()
                w.writerow([r.condition if k == "conditions" else d[k] for k in keys])
    write_atomically(out / "summary.csv", write_csv)
    write_atomically(out / "summary.json", strict_json(dict(results=[r.to_dict() for r in results],
                                                            controller_ns_per_call=costs)))
    plot_study(out, results, drive)

    lines = ["# Ferrari versus 2-D tables on a drive cycle", "",
             "Produced by `python -m scenarios compare`. Every run steps the IpmsmDrive FMU (the controller and",
             "the plant coupled inside at 100 µs) with the vehicle, driver and battery at 10 ms",
             "(scenarios/runs/simulate.py); each method's own commands (command_check 0). The tables",
             f"are 41 × 41, built by the controller at initialisation for {U_DC_NOMINAL_V:.0f} V and "
             f"{T_REFERENCE_K - ZERO_CELSIUS_K:.0f} °C with the exact solver.",
             "*Copper loss vs optimum*: the run's copper loss over that of the exact optimum (Ferrari,",
             "recursion 2, the same delivered torque and conditions, evaluated every 10 ms). *Torque error*:",
             "delivered T_e (least loss: the shaft torque) against the controller's own clamped command T_cmd,",
             "10-ms means. *Time above",
             "V_max / voltage-limited*: share of the cycle (sampled every 10 ms) in which the current regulator's",
             "voltage exceeded the planned V_max = k_u u_dc/√3, and in which it hit the inverter's linear range "
             "u_dc/√3. The optimum keeps 5 % of it in reserve (k_u = 0.95); a method",
             "whose commands fall outside the voltage ellipse spends that reserve (and shows copper loss *below*",
             "the optimum's) or, past it, loses torque.",
             "*Drive loss*: copper + iron + inverter (E_cu + E_fe + E_inv). *Loss vs least-loss optimum*: the",
             "run's drive loss over that of the least-loss optimum (Ferrari, objective 1, recursion 2, at the",
             "same delivered shaft torque and conditions, evaluated every 10 ms; docs/least_loss.md). The",
             "least-loss rows (objective 1: `least loss`) are Ferrari's online least loss and the 2-D tables",
             f"made for least loss at {U_DC_NOMINAL_V:.0f} V and {T_REFERENCE_K - ZERO_CELSIUS_K:.0f} °C; "
             "their torques are shaft torques.", ""]
    measured = any(ns is not None for ns in costs.values())  # bench_controller's figures, where it is built
    if not measured:
        lines += ["*Controller cost per call*: not measured here; `build/bin/bench_controller` gives it, built with",
                  "`cmake -S . -B build -DIPMSM_BUILD_BENCH=ON` (docs/performance.md).", ""]
    for cycle in dict.fromkeys(r.summary.cycle for r in results):
        for cond in dict.fromkeys(r.condition for r in results if r.summary.cycle == cycle):
            lines += [f"## {cycle}, {cond}", "",
                      "| method | Wh/km | speed RMSE (km/h) | torque error RMS / max (N·m) | copper loss vs optimum "
                      "| current excess RMS (A) | time above V_max / voltage-limited | drive loss (Wh) | "
                      "loss vs least-loss optimum | " + ("controller ns/call | " if measured else "") + "memory |",
                      "|---|---|---|---|---|---|---|---|---|" + ("---|" if measured else "") + "---|"]
            for r in results:
                s = r.summary
                if s.cycle != cycle or r.condition != cond:
                    continue
                ns = costs.get(r.variant)
                lines.append(f"| {r.variant} | {s.Wh_per_km:.2f} | {s.speed_rmse_mps * 3.6:.2f} | "
                             f"{s.torque_rmse_Nm:.3f} / {s.torque_error_max_Nm:.2f} | {_copper_excess(s):+.2%} | "
                             f"{s.current_excess_rms_A:.2f} | {s.time_above_V_max_pct:.1f} % / "
                             f"{s.time_voltage_limited_pct:.1f} % | {s.drive_loss_Wh:.1f} | {_pct(loss_excess(s))} | "
                             + (f"{f'{ns:.0f}' if ns else '–'} | " if measured else "") + f"{_memory(s)} |")
            lines.append("")
            lines += _thermal_lines([r for r in results if r.summary.cycle == cycle and r.condition == cond])
    lines += ["![Study](study.png)", "",
              "Per-run pictures: `runs/*/run.png`; traces: `runs/*/trace.csv`; all figures: `summary.csv`."]
    write_atomically(out / "report.md", "\n".join(lines) + "\n")


def _thermal_lines(results: list[StudyRun]) -> list[str]:
    """The thermal network's figures of a condition's runs (none when it was off): how hot the
    magnets and windings got along the cycle, which is what the tables were not made for."""
    runs = [r for r in results if r.summary.thermal_network]
    if not runs:
        return []
    c = runs[0].summary.conditions
    lines = [f"The machine's thermal network (docs/thermal.md) heats the magnets and windings from "
             f"{c['T_magnet'] - ZERO_CELSIUS_K:.0f} °C along the cycle; the controller is told the network's "
             "temperatures of the step before; the tables are those made for "
             f"{c['lut_T_magnet'] - ZERO_CELSIUS_K:.0f} °C.", "",
             "| method | magnets: max / end (°C) | winding: max / end (°C) | heat into coolant / ambient / "
             "stored (Wh) |", "|---|---|---|---|"]
    for r in runs:
        s = r.summary
        lines.append(f"| {r.variant} | {s.theta_magnet_max_K - ZERO_CELSIUS_K:.1f} / "
                     f"{s.theta_magnet_end_K - ZERO_CELSIUS_K:.1f} | {s.theta_winding_max_K - ZERO_CELSIUS_K:.1f} / "
                     f"{s.theta_winding_end_K - ZERO_CELSIUS_K:.1f} | {s.heat_coolant_Wh:.1f} / "
                     f"{s.heat_ambient_Wh:.1f} / {s.heat_stored_Wh:.1f} |")
    return lines + [""]


def plot_study(out: Path, results: list[StudyRun], drive=None) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from scenarios.runs.plots import plot_run
    for r in results:
        plot_run(out / r.run_dir, f"{r.summary.cycle}, {r.condition}, {r.variant}", drive)
    conds = list(dict.fromkeys(r.condition for r in results))
    variants = list(dict.fromkeys(r.variant for r in results))
    cycle = results[0].summary.cycle
    fig, ax = plt.subplots(1, 4, figsize=(21, 4.8))
    x = np.arange(len(conds))
    wdt = 0.8 / len(variants)
    for j, v in enumerate(variants):
        sel = {r.condition: r.summary for r in results if r.variant == v and r.summary.cycle == cycle}
        torque = [sel[c].torque_rmse_Nm if c in sel else np.nan for c in conds]
        copper = [100 * _copper_excess(sel[c]) if c in sel else np.nan for c in conds]
        energy = [sel[c].Wh_per_km if c in sel else np.nan for c in conds]
        loss = [100 * loss_excess(sel[c]) if c in sel else np.nan for c in conds]
        ax[0].bar(x + j * wdt, torque, wdt, label=v)
        ax[1].bar(x + j * wdt, copper, wdt)
        ax[2].bar(x + j * wdt, energy, wdt)
        ax[3].bar(x + j * wdt, loss, wdt)
    for a, t in zip(ax, ("torque error RMS (N·m)", "copper loss above the optimum (%)", "battery energy (Wh/km)",
                         "drive loss above the least-loss optimum (%)")):
        a.set_xticks(x + 0.4 - wdt / 2, [textwrap.fill(c, 12) for c in conds], fontsize=8)
        a.set_title(t)
        a.grid(alpha=0.3, axis="y")
    ax[2].set_ylim(bottom=min(r.summary.Wh_per_km for r in results) * 0.97)
    ax[0].legend(fontsize=7)
    fig.suptitle(f"{cycle}: Ferrari versus 2-D tables, least current and least loss")
    fig.tight_layout()
    write_atomically(out / "study.png", lambda p: fig.savefig(p, format="png", dpi=100))
    plt.close(fig)
