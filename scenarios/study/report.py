"""A study's report from DIR/runs.parquet alone (no trace, no re-run): report.md (per drive,
cycle and condition, one line per method; then the failed runs with their messages) and
study.png. `python -m scenarios study --report-only DIR` makes it again."""
from __future__ import annotations

import math
from pathlib import Path

import pyarrow as pa

from scenarios.core.boundary import write_atomically
from scenarios.study import table

#: groups (drive, cycle, condition) drawn in study.png at most: a picture, not the table
PLOT_GROUPS_MAX = 60


def variant_label(method: str, recursion: int, objective: str | None = "current") -> str:
    """The compare study's name of a variant (method, recursion, objective), else one made of them."""
    from scenarios.study.compare import LEAST_LOSS_VARIANTS, VARIANTS
    objective = objective or "current"
    return next((v.label for v in VARIANTS + LEAST_LOSS_VARIANTS
                 if (v.method, v.recursion, v.objective) == (method, recursion, objective)),
                f"{method}, recursion {recursion}" + ("" if objective == "current" else f", least {objective}"))


def _label(r: dict) -> str:
    grid = f", {r['lut_n_torque']} x {r['lut_n_speed']} points" if r["lut_n_torque"] is not None else ""
    return variant_label(r["method"], r["recursion"], r.get("objective")) + grid


def _copper_excess(r: dict) -> float:
    """The run's copper loss over the optimum's, less 1 (NaN without the optimum)."""
    opt, cu = r["copper_loss_optimal_Wh"], r["copper_loss_Wh"]
    return cu / opt - 1 if opt and not table.is_nan(opt) and not table.is_nan(cu) else math.nan


def _loss_excess(r: dict) -> float:
    """The run's drive loss (copper + iron + inverter) over the least-loss optimum's, less 1 (NaN
    without that optimum: FMUs without the least-loss controller, or rows of older studies)."""
    opt, loss = r.get("drive_loss_optimal_Wh"), r.get("drive_loss_Wh")
    return loss / opt - 1 if opt and not table.is_nan(opt) and not table.is_nan(loss) else math.nan


def _num(x, fmt: str, scale: float = 1.0) -> str:
    """A figure of the table, or "–" where it is undefined (None or NaN: e.g. Wh/km of a window
    in which the car stands)."""
    return "–" if table.is_nan(x) else format(x * scale, fmt)


def _where(r: dict) -> str:
    drive = Path(r["drive"]).stem if r["drive"] else "default drive"
    window = "" if table.is_nan(r["window_start_s"]) else f" [{r['window_start_s']:g}, {r['window_end_s']:g}] s"
    return f"{drive}, {Path(r['cycle']).stem}{window}, {r['condition']}"


def _order(r: dict) -> tuple:
    return (r["drive"], r["cycle"], r["window_start_s"] if not table.is_nan(r["window_start_s"]) else -1.0,
            -r["u_dc_scale"], r["T_magnet_degC"], r["T_winding_degC"], r.get("objective") or "current", r["method"],
            r["recursion"])


def write_report(out: Path, runs: pa.Table | None = None) -> Path:
    """report.md and study.png in `out`, from its runs.parquet (or `runs`)."""
    out = Path(out)
    rows = sorted((runs if runs is not None else table.read_runs(out)).to_pylist(), key=_order)
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    builds = sorted({r["fmu_hash"] for r in rows if r["fmu_hash"]})
    codes = sorted({r["code_hash"] for r in rows if r["code_hash"]})
    lines = ["# Study", "",
             f"{len(rows)} runs in `runs.parquet`: {len(ok)} ok, {len(failed)} failed. FMU build "
             f"{', '.join(builds) or '–'}; scenarios code {', '.join(codes) or '–'}"
             + (" (**several builds or code versions: compare rows of one only**)" if len(builds) + len(codes) > 2
                else "") + ".",
             "Made from runs.parquet alone (`python -m scenarios study --report-only DIR`). Traces:",
             "`traces/<key>.parquet`. Copper loss vs optimum: the run's copper loss over that of the exact",
             "optimum (Ferrari, recursion 2) at the same delivered torque and conditions. Torque error: the",
             "delivered T_e against the controller's clamped command T_cmd, 10-ms means. Loss vs least-loss",
             "optimum: the run's copper + iron + inverter loss over the least-loss optimum's (objective 1) at the",
             "same delivered shaft torque and conditions.", ""]
    groups: dict[str, list[dict]] = {}
    for r in ok:
        groups.setdefault(_where(r), []).append(r)
    for where, rs in groups.items():
        lines += [f"## {where}", "",
                  "| method | Wh/km | speed RMSE (km/h) | torque error RMS / max (N·m) | copper loss vs optimum "
                  "| current excess RMS (A) | time above V_max / voltage-limited | loss copper / iron / inverter (Wh) "
                  "| loss vs least-loss optimum | run wall (s) | key |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rs:
            lines.append(f"| {_label(r)} | {_num(r['Wh_per_km'], '.2f')} | "
                         f"{_num(r['speed_rmse_mps'], '.2f', 3.6)} | "
                         f"{_num(r['torque_rmse_Nm'], '.3f')} / {_num(r['torque_error_max_Nm'], '.2f')} | "
                         f"{_num(_copper_excess(r), '+.2%')} | {_num(r['current_excess_rms_A'], '.2f')} | "
                         f"{_num(r['time_above_V_max_pct'], '.1f')} % / "
                         f"{_num(r['time_voltage_limited_pct'], '.1f')} % | "
                         f"{_num(r['copper_loss_Wh'], '.1f')} / {_num(r['iron_loss_Wh'], '.1f')} / "
                         f"{_num(r['inverter_loss_Wh'], '.1f')} | {_num(_loss_excess(r), '+.2%')} | "
                         f"{_num(r['run_wall_s'], '.1f')} | `{r['key']}` |")
        lines.append("")
    if failed:
        lines += ["## Failed runs", "", "| run | method | key | error |", "|---|---|---|---|"]
        for r in failed:
            err = (r["error"] or "").replace("|", "\\|").replace("\n", " ")
            lines.append(f"| {_where(r)} | {_label(r)} | `{r['key']}` | {err} |")
        lines.append("")
    if ok:
        plot_study(out, groups)
        lines += ["![Study](study.png)", ""]
    return write_atomically(out / "report.md", "\n".join(lines))


def plot_study(out: Path, groups: dict[str, list[dict]]) -> Path:
    """study.png: torque error, copper loss above the optimum and energy per group and method."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    names = list(groups)[:PLOT_GROUPS_MAX]
    variants = list(dict.fromkeys(_label(r) for rs in groups.values() for r in rs))
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.8 + 0.12 * len(names)))
    x = np.arange(len(names))
    wdt = 0.8 / len(variants)
    for j, v in enumerate(variants):
        sel = [{_label(r): r for r in groups[n]}.get(v) for n in names]
        def col(f, sel=sel):
            return [np.nan if not r or table.is_nan(f(r)) else f(r) for r in sel]
        ax[0].barh(x + j * wdt, col(lambda r: r["torque_rmse_Nm"]), wdt, label=v)
        ax[1].barh(x + j * wdt, col(lambda r: 100 * _copper_excess(r)), wdt)
        ax[2].barh(x + j * wdt, col(lambda r: r["Wh_per_km"]), wdt)
    for i, (a, t) in enumerate(zip(ax, ("torque error RMS (N·m)", "copper loss above the optimum (%)",
                                        "battery energy (Wh/km)"))):
        a.set_yticks(x + 0.4 - wdt / 2, names if i == 0 else [""] * len(names), fontsize=7)
        a.set_title(t)
        a.grid(alpha=0.3, axis="x")
    ax[0].legend(fontsize=7)
    if len(groups) > len(names):
        fig.suptitle(f"the first {len(names)} of {len(groups)} groups (all in report.md and runs.parquet)", fontsize=9)
    fig.tight_layout()
    path = out / "study.png"
    write_atomically(path, lambda p: fig.savefig(p, format="png", dpi=90))
    plt.close(fig)
    return path
