"""python -m scenarios map show FILE: the machine of a flux map at a glance, `map.png` (one figure,
eight panels), `map.md` (the numbers) and `map.json` (the same, for programs).

Where each number comes from:
- psi_d, psi_q, apparent and incremental inductances, reciprocity: the map itself, through
  scenarios.maps.flux_map's bicubic splines (scipy; independent of the FMUs' C++ interpolation).
  Reciprocity is dpsi_d/di_q - dpsi_q/di_d, at the grid nodes inside the current limit.
- torque-speed envelope, MTPA and MTPV: the IpmsmController FMU (Ferrari, recursion 2: the
  optimum on the map), one step per point: T_max, i_d_ref, i_q_ref, region (4 = MTPV).
- efficiency map (motoring, torque x speed): the IpmsmDrive FMU (controller, plant on CVODE and
  inverter loss model in one), held at each point for 2 x 10 ms (the current loop settles within
  the first step; more steps while P_dc still moves): eta = P_mech / P_dc, so the motor's copper
  and iron losses (plant) and the inverter's conduction and switching losses are all in it.

Machine parameters: a drive description's (--drive), else the map's '# key: value' metadata
where it has them, else the default motor's, each such assumption listed in map.md
(scenarios.maps.machine).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from scenarios.core.boundary import strict_json, write_atomically
from scenarios.core.paths import BUILD_DIR
from scenarios.core.progress import Progress
from scenarios.cosim.fmu import CosimError, Fmu
from scenarios.maps.error import MapImportError
from scenarios.maps.flux_map import FluxMap, read_flux_map
from scenarios.maps.importer import contract_csv
from scenarios.maps.machine import machine_values

RPM = 2 * math.pi / 60  # rad/s per r/min
SQRT3 = math.sqrt(3.0)
T_REF_HUGE = 1e5        # N m: a torque command beyond any machine's reach, to read T_max
STEP = 1e-4             # s, the controller's step (its default sample time)
DRIVE_DT = 0.01         # s, the drive's communication step (a vehicle tool's)
DRIVE_SETTLE_REL = 1e-4  # P_dc steady when a step changes it by less than this (relative, + 1 W)
DRIVE_MAX_STEPS = 6

@dataclass(frozen=True)
class ShowSpec:
    n_speed: int = 41          # envelope points, 0 ... top speed
    n_mtpa: int = 25           # MTPA points, 0 ... peak torque
    n_eff_speed: int = 30      # efficiency map
    n_eff_torque: int = 24


@dataclass
class MachineSummary:
    """The numbers of map.md (SI units)."""

    map_file: str
    grid: str
    psi_m_Wb: float
    parameters: dict           # FMU parameters used
    assumed: list              # parameters not in the map's metadata
    u_dc_V: float
    V_max_V: float
    T_peak_Nm: float           # T_max at standstill
    w_base_rad_s: float        # the highest speed on the envelope with T_max >= 99 % of T_peak
    T_at_base_Nm: float        # T_max at w_base (from the envelope's own point there)
    P_max_W: float
    w_top_rad_s: float
    reciprocity_max_H: float   # max |dpsi_d/di_q - dpsi_q/di_d| inside the current limit
    reciprocity_rel: float     # ... relative to the largest incremental self-inductance there
    reciprocity_at_A: list     # (i_d, i_q) where
    mtpv_points: int           # envelope points in region 4 (MTPV)
    eta_max: float
    eta_max_at: list           # (speed rad/s, torque N m)
    loss_source: str
    envelope: dict = field(default_factory=dict)  # speed_rad_s, T_max_Nm, P_W, region
    wall_s: float = 0.0
    # least current against least loss (scenarios.maps.objectives; empty: FMUs without `objective`)
    objective_maps: dict = field(default_factory=dict)
    least_loss_note: str = ""


def machine_parameters(fmap: FluxMap, u_dc: float | None, I_max: float | None = None,
                       drive=None) -> tuple[dict, list, float]:
    """FMU parameters: a drive description's motor (scenarios.drives.description) if given, else
    the map's metadata with each missing value named (scenarios.maps.machine); u_dc and I_max
    given override both."""
    if drive is not None:
        m = drive.motor
        given = {k: getattr(m, k) for k in ("pole_pairs", "R_s", "I_max", "T_magnet_ref", "T_winding_ref", "alpha_cu",
                                            "k_psi_T", "fe_k_h", "fe_alpha", "fe_k_e", "fe_psi_ref", "w_m_max")}
        given.update(k_u=drive.controller.k_u, lut_u_dc=drive.controller.lut_u_dc)
        assumed = [f"{a} (drive {drive.name})" for a in drive.assumed]
        values, _ = machine_values(fmap, given)
    else:
        values, assumed = machine_values(fmap, {})
    if I_max is not None:
        values["I_max"] = float(I_max)
        assumed = [a for a in assumed if not a.startswith("I_max")]
    if u_dc is not None:
        values["lut_u_dc"] = float(u_dc)
        assumed = [a for a in assumed if not a.startswith("lut_u_dc")]
    u = float(values.pop("lut_u_dc"))
    if values["w_m_max"] is None:
        values.pop("w_m_max")
    return values, assumed, u


CONTROLLER_PARAMS = ("pole_pairs", "R_s", "I_max", "k_u", "T_magnet_ref", "k_psi_T")


def reciprocity(fmap: FluxMap, I_max: float):
    """dpsi_d/di_q - dpsi_q/di_d on the grid (H), and its largest magnitude inside |i| <= I_max:
    (mismatch grid, max, max relative to the largest incremental self-inductance, (i_d, i_q))."""
    I_d, I_q = np.meshgrid(fmap.i_d, fmap.i_q, indexing="ij")
    L_dd, L_qd = fmap.flux_on_grid(fmap.i_d, fmap.i_q, dx=1)
    L_dq, L_qq = fmap.flux_on_grid(fmap.i_d, fmap.i_q, dy=1)
    mismatch = L_dq - L_qd
    inside = np.hypot(I_d, I_q) <= I_max * (1 + 1e-12)
    k = np.unravel_index(np.argmax(np.where(inside, np.abs(mismatch), -1.0)), mismatch.shape)
    scale = max(np.abs(L_dd[inside]).max(), np.abs(L_qq[inside]).max())
    return mismatch, float(abs(mismatch[k])), float(abs(mismatch[k]) / scale), [float(I_d[k]), float(I_q[k])]


def controller_curves(fmu_path: Path, csv: Path, params: dict, u_dc: float, T_magnet: float, spec: ShowSpec,
                      w_top: float | None, bar: Progress, fmap: FluxMap):
    """Envelope (speeds, T_max, region, i_d, i_q), MTPA (i_d, i_q, T) from the controller FMU."""
    cp = {k: v for k, v in params.items() if k in CONTROLLER_PARAMS}
    with Fmu(fmu_path, flux_map=str(csv), recursion=2, **cp) as c:
        k = [0]

        def at(T_ref, w_m):
            c.set(T_ref=T_ref, w_m=w_m, u_dc=u_dc, T_magnet=T_magnet, i_d=0.0, i_q=0.0)
            c.step(k[0] * STEP, STEP)
            k[0] += 1
            return c.get("T_max", "i_d_ref", "i_q_ref", "region")

        T_peak, i_d0, i_q0, _ = at(T_REF_HUGE, 0.0)
        if w_top is None:  # four times the speed where the peak-torque flux meets the voltage limit
            fm = fmap
            psi = math.hypot(*(float(x) for x in fm.flux(i_d0, i_q0)))
            w_top = 4.0 * (params["k_u"] * u_dc / SQRT3) / (psi * params["pole_pairs"])
        speeds = np.linspace(0.0, w_top, spec.n_speed)
        env = []
        for w in speeds:
            env.append(at(T_REF_HUGE, w))
            bar.update()
        torques = np.linspace(0.0, T_peak, spec.n_mtpa)
        mtpa = []
        for T in torques:
            _, i_d, i_q, _ = at(T, 0.0)
            mtpa.append((i_d, i_q, T))
            bar.update()
    env = np.array(env, dtype=float)
    return speeds, env, np.array(mtpa), float(T_peak)


def efficiency_map(drive_path: Path, csv: Path, params: dict, u_dc: float, T_magnet: float, speeds, torques,
                   bar: Progress):
    """eta = P_mech / P_dc (and the losses) over speeds x torques from the IpmsmDrive FMU;
    NaN beyond the torque it can reach there."""
    from scenarios.cosim.drive_fmu import DriveFmu

    shape = (len(speeds), len(torques))
    eta, P_cu, P_fe, P_inv = (np.full(shape, np.nan) for _ in range(4))
    with DriveFmu(drive_path, params=dict(params, flux_map=str(csv)), u_dc=u_dc, T_magnet=T_magnet,
                  T_winding=params["T_winding_ref"]) as d:
        for a, w in enumerate(speeds):
            for b, T in enumerate(torques):
                bar.update()
                last = None
                for _ in range(DRIVE_MAX_STEPS):
                    r = d.advance(DRIVE_DT, T, w, u_dc, T_magnet, params["T_winding_ref"])
                    if last is not None and abs(r.P_dc - last) <= DRIVE_SETTLE_REL * abs(r.P_dc) + 1.0:
                        break
                    last = r.P_dc
                if r.T_cmd < T * (1 - 1e-9) or r.P_dc <= 0.0 or r.P_mech <= 0.0:
                    continue  # beyond reach at this speed (or no motoring: no efficiency)
                eta[a, b] = r.P_mech / r.P_dc
                P_cu[a, b], P_fe[a, b], P_inv[a, b] = r.P_cu, r.P_fe, r.P_inv
    return eta, P_cu, P_fe, P_inv


def show_map(path: str | Path, out: str | Path, u_dc: float | None = None, I_max: float | None = None,
             build: Path = BUILD_DIR, spec: ShowSpec | None = None, drive=None) -> MachineSummary:
    """Write out/map.png, out/map.md and out/map.json for the flux map at `path` (CSV or .mat)."""
    from scenarios.maps.show_plot import plot_machine

    spec = spec or ShowSpec()
    t0 = time.perf_counter()
    path, out = Path(path), Path(out)
    csv = contract_csv(path)
    fmap = read_flux_map(csv)
    params, assumed, u_dc = machine_parameters(fmap, u_dc, I_max, drive)
    T_magnet = params["T_magnet_ref"]
    V_max = params["k_u"] * u_dc / SQRT3
    bar = Progress(spec.n_speed + spec.n_mtpa + spec.n_eff_speed * spec.n_eff_torque, "map show")
    try:
        speeds, env, mtpa, T_peak = controller_curves(build / "fmu" / "IpmsmController.fmu", csv, params, u_dc,
                                                      T_magnet, spec, params.get("w_m_max"), bar, fmap)
    except Exception as e:  # fmpy raises Exception on an fmi2Error status
        raise MapImportError(path, "flux_map", "a map and parameters the IpmsmController FMU accepts "
                             f"({', '.join(f'{k} = {v:g}' for k, v in params.items())})", str(e)) from e
    T_env = env[:, 0]
    base = int(np.nonzero(T_env >= 0.99 * T_peak)[0].max())
    P = T_env * speeds
    eff_speeds = np.linspace(speeds[-1] / spec.n_eff_speed, speeds[-1], spec.n_eff_speed)
    eff_torques = np.linspace(T_peak / spec.n_eff_torque, T_peak, spec.n_eff_torque)
    loss_source = (f"IpmsmDrive FMU (plant copper + iron loss, inverter conduction + switching loss), held "
                   f"{DRIVE_DT * 1e3:g} ms steps until P_dc settles")
    try:
        eta, P_cu, P_fe, P_inv = efficiency_map(build / "fmu" / "IpmsmDrive.fmu", csv, params, u_dc, T_magnet,
                                                eff_speeds, eff_torques, bar)
    except CosimError as e:  # e.g. a map the plant cannot invert (it folds): the rest still holds
        eta = P_cu = P_fe = P_inv = np.full((len(eff_speeds), len(eff_torques)), np.nan)
        loss_source = f"none: {e}"
    bar.close()
    mismatch, rec_max, rec_rel, rec_at = reciprocity(fmap, params["I_max"])
    k_eta = np.unravel_index(np.nanargmax(eta), eta.shape) if np.isfinite(eta).any() else None
    s = MachineSummary(
        map_file=str(path), grid=f"{len(fmap.i_d)} x {len(fmap.i_q)} (i_d {fmap.i_d[0]:g} ... {fmap.i_d[-1]:g} A, "
                                 f"i_q {fmap.i_q[0]:g} ... {fmap.i_q[-1]:g} A)",
        psi_m_Wb=fmap.psi_m, parameters=params, assumed=assumed, u_dc_V=u_dc, V_max_V=V_max, T_peak_Nm=T_peak,
        w_base_rad_s=float(speeds[base]), T_at_base_Nm=float(T_env[base]), P_max_W=float(P.max()),
        w_top_rad_s=float(speeds[-1]), reciprocity_max_H=rec_max, reciprocity_rel=rec_rel, reciprocity_at_A=rec_at,
        mtpv_points=int((env[:, 3] == 4).sum()),
        eta_max=float(eta[k_eta]) if k_eta else float("nan"),
        eta_max_at=[float(eff_speeds[k_eta[0]]), float(eff_torques[k_eta[1]])] if k_eta else [],
        loss_source=loss_source,
        envelope=dict(speed_rad_s=speeds.tolist(), T_max_Nm=T_env.tolist(), P_W=P.tolist(),
                      region=env[:, 3].astype(int).tolist()))
    out.mkdir(parents=True, exist_ok=True)
    plot_machine(out / "map.png", fmap, s, env, speeds, mtpa, mismatch, eff_speeds, eff_torques, eta)
    both_objectives(s, build / "fmu" / "IpmsmController.fmu", csv, fmap, params, u_dc, T_magnet, eff_speeds,
                    eff_torques, drive, out)
    s.wall_s = time.perf_counter() - t0
    write_atomically(out / "map.json", strict_json(asdict(s), indent=1))  # an undefined figure: null
    write_atomically(out / "map.md", markdown(s, P_cu, P_fe, P_inv))
    return s


def both_objectives(s: MachineSummary, fmu_path: Path, csv: Path, fmap: FluxMap, params: dict, u_dc: float,
                    T_magnet: float, speeds, torques, drive, out: Path) -> None:
    """Least current's and least loss's efficiency maps and their difference (objectives.png,
    s.objective_maps), where the controller FMU has the least-loss controller."""
    from scenarios.core.fmu_ranges import controller_has_objective
    from scenarios.maps.objectives import IRON_LOSS_PARAMS, objective_maps, plot_objectives
    if not controller_has_objective():
        s.least_loss_note = "not drawn: the built FMUs have no `objective` parameter (rebuild them)"
        return
    # a drive's loss models; else the map's iron loss and the FMU's own inverter (its defaults)
    loss_params = drive.loss_params() if drive is not None else {k: params[k] for k in IRON_LOSS_PARAMS}
    bar = Progress(len(speeds) * len(torques), "map show: least current, least loss")
    try:
        m = objective_maps(fmu_path, csv, fmap, params, loss_params, u_dc, T_magnet, speeds, torques, bar)
    except CosimError as e:
        s.least_loss_note = f"not drawn: {e}"
        return
    finally:
        bar.close()
    plot_objectives(out / "objectives.png", m, Path(s.map_file).name)
    s.objective_maps = asdict(m)
    d = m.difference_pct()
    if np.isfinite(d).any():
        k = np.unravel_index(np.nanargmax(d), d.shape)
        both = np.isfinite(d)
        s.least_loss_note = (f"least loss gains up to {d[k]:.2f} efficiency points (at {speeds[k[0]] / RPM:.0f} r/min, "
                             f"{torques[k[1]]:.1f} N m), {np.nanmean(d):.3f} points on average over the "
                             f"{int(both.sum())} points both reach; least current is never better by more than "
                             f"{max(0.0, -float(np.nanmin(d))):.2g} points")


def markdown(s: MachineSummary, P_cu, P_fe, P_inv) -> str:
    p = s.parameters
    rows = [
        ("flux map", f"`{s.map_file}`"),
        ("grid", s.grid),
        ("psi_m = psi_d(0, 0)", f"{s.psi_m_Wb:.5g} Wb"),
        ("pole pairs, R_s, I_max", f"{p['pole_pairs']}, {p['R_s']:g} Ohm, {p['I_max']:g} A"),
        ("u_dc, V_max = k_u u_dc / sqrt 3", f"{s.u_dc_V:g} V, {s.V_max_V:.4g} V"),
        ("peak torque (T_max at standstill)", f"{s.T_peak_Nm:.2f} N m"),
        ("base speed (T_max >= 99 % of peak)", f"{s.w_base_rad_s / RPM:.0f} r/min"),
        ("peak torque at base speed", f"{s.T_at_base_Nm:.2f} N m"),
        ("peak power", f"{s.P_max_W / 1e3:.2f} kW"),
        ("reciprocity max abs(dpsi_d/di_q - dpsi_q/di_d)",
         f"{s.reciprocity_max_H * 1e6:.4g} uH ({100 * s.reciprocity_rel:.3g} % of the largest incremental "
         f"inductance), at i_d = {s.reciprocity_at_A[0]:g} A, i_q = {s.reciprocity_at_A[1]:g} A"),
        ("envelope points on MTPV (region 4)", f"{s.mtpv_points} of {len(s.envelope['speed_rad_s'])}"),
        ("peak efficiency (motor + inverter)",
         f"{100 * s.eta_max:.2f} % at {s.eta_max_at[0] / RPM:.0f} r/min, {s.eta_max_at[1]:.1f} N m"
         if s.eta_max_at else "not available (see below)"),
    ]
    lines = [f"# Machine at a glance: `{Path(s.map_file).name}`", "",
             "Made by `python -m scenarios map show`; the figure is `map.png`, the numbers also in `map.json`.", "",
             "| quantity | value |", "|---|---|"] + [f"| {a} | {b} |" for a, b in rows]
    lines += ["", "## Torque-speed envelope (IpmsmController FMU, Ferrari, recursion 2)", "",
              "| speed (r/min) | T_max (N m) | P (kW) | region |", "|---:|---:|---:|---:|"]
    e = s.envelope
    for w, T, P, r in list(zip(e["speed_rad_s"], e["T_max_Nm"], e["P_W"], e["region"]))[::4]:
        lines.append(f"| {w / RPM:.0f} | {T:.2f} | {P / 1e3:.2f} | {r} |")
    lines += ["", "## Sources and assumptions", "",
              "- flux linkages, inductances, reciprocity: the map's bicubic splines (scenarios/flux_map.py)",
              "- envelope, MTPA, MTPV: the IpmsmController FMU, one step per point",
              f"- efficiency: {s.loss_source}; largest losses on the map: copper {np.nanmax(P_cu) / 1e3:.2f} kW, "
              f"iron {np.nanmax(P_fe) / 1e3:.2f} kW, inverter {np.nanmax(P_inv) / 1e3:.2f} kW"
              if np.isfinite(P_cu).any() else f"- efficiency: {s.loss_source}"]
    lines += [f"- assumed: {a}" for a in s.assumed] or ["- every parameter from the map's metadata"]
    lines += ["", "## Least current against least loss", "",
              f"Efficiency `P_mech / (P_mech + P_loss_cmd)` of both objectives over shaft torque x speed, from the "
              f"IpmsmController FMU's predicted loss of each command (`objectives.png`; scenarios/maps/objectives.py): "
              f"{s.least_loss_note or 'not drawn'}."]
    lines += ["", f"Wall time {s.wall_s:.1f} s.", ""]
    return "\n".join(lines)
