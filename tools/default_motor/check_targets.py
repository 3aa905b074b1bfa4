"""Check the default motor's targets on its flux map, by brute force; plot envelope and efficiency.

    python -m tools.default_motor.check_targets [--csv FILE] [--out-dir DIR] [--no-plots]

Works only from the CSV (flux linkages and '# key: value' metadata), not from the model that
generated it: the map is interpolated by bicubic splines, and for every speed the optimal
currents are found by exhaustive search over a 1 A grid of the current disc |i| <= I_max, keeping
the points whose steady-state voltage (v_d = R_s i_d - w psi_q, v_q = R_s i_q + w psi_d) is within
V_max = k_u u_dc / sqrt(3). The envelope is the largest torque of the feasible points; the
efficiency map takes, for each shaft torque, the feasible point of least current magnitude
(copper-loss minimising, like the controller), with copper and iron loss.

Everything holds at the map's reference temperatures (R_s at T_winding_ref, magnets at
T_magnet_ref) and in motoring; generating mirrors it (i_q -> -i_q) apart from the loss signs.
Writes docs/motor/targets.json, docs/motor/torque_speed_envelope.png, docs/motor/efficiency_map.png
and docs/motor/flux_linkages.png.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from scenarios.maps.flux_map import DEFAULT_MAP, read_flux_map

from .iron_loss import IronLossCoefficients

REPO_ROOT = Path(__file__).resolve().parents[2]
RPM = 30 / math.pi  # r/min per rad/s


class Drive:
    """The map's machine with its drive limits, as the metadata describe it."""

    def __init__(self, path):
        self.map = read_flux_map(path)
        num = self.map.number
        self.p = int(num("pole_pairs"))
        self.R_s = num("R_s_ohm")
        self.I_max = num("I_max_A")
        self.u_dc = num("u_dc_V")
        self.k_u = num("k_u")
        self.V_max = self.k_u * self.u_dc / math.sqrt(3)
        self.w_m_max = num("w_m_max_rad_s")
        self.fe = IronLossCoefficients(
            k_h=num("fe_k_h_W_per_Hz"), alpha=num("fe_alpha"), k_e=num("fe_k_e_W_per_Hz2"), psi_ref=num("fe_psi_ref_Wb")
        )

    def psi(self, i_d, i_q, dx=0, dy=0):
        """Interpolated psi_d, psi_q (or their derivatives) at scattered points."""
        return self.map.flux(i_d, i_q, dx=dx, dy=dy)


class Candidates:
    """A polar grid of the current quarter disc i_d <= 0 <= i_q, |i| <= I_max: rays x radii."""

    def __init__(self, drive: Drive, step_A=1.0, step_deg=0.05):
        self.r = np.linspace(0.0, drive.I_max, int(round(drive.I_max / step_A)) + 1)
        self.theta = np.radians(np.linspace(90.0, 180.0, int(round(90 / step_deg)) + 1))
        th, r = np.meshgrid(self.theta, self.r, indexing="ij")  # [ray, radius]
        self.i_d, self.i_q = r * np.cos(th), r * np.sin(th)
        self.i_d[:, 0] = 0.0
        self.psi_d, self.psi_q = drive.psi(self.i_d, self.i_q)
        self.T_e = 1.5 * drive.p * (self.psi_d * self.i_q - self.psi_q * self.i_d)
        self.psi_mag = np.hypot(self.psi_d, self.psi_q)
        self.drive = drive

    def voltage_ok(self, i_d, i_q, psi_d, psi_q, w_m):
        """Steady-state voltage within V_max at mechanical speed w_m (rad/s)?"""
        dr = self.drive
        w = dr.p * w_m
        return (dr.R_s * i_d - w * psi_q) ** 2 + (dr.R_s * i_q + w * psi_d) ** 2 <= dr.V_max**2

    def shaft_torque(self, psi_mag, T_e, w_m):
        return T_e - self.drive.fe.drag_torque(psi_mag, w_m, self.drive.p)


def envelope(c: Candidates, speeds):
    """Largest electromagnetic and shaft torque over the feasible grid points at each speed."""
    T_e_max, T_sh_max, P_fe_at = (np.full(len(speeds), np.nan) for _ in range(3))
    i_at = np.full((len(speeds), 2), np.nan)
    for n, w in enumerate(speeds):
        ok = c.voltage_ok(c.i_d, c.i_q, c.psi_d, c.psi_q, w)
        if not ok.any():
            continue
        T_sh = np.where(ok, c.shaft_torque(c.psi_mag, c.T_e, w), -np.inf)
        T_e_max[n] = c.T_e[ok].max()
        best = np.unravel_index(np.argmax(T_sh), T_sh.shape)
        T_sh_max[n] = T_sh[best]
        P_fe_at[n] = c.drive.fe.loss_at_speed(c.psi_mag[best], w, c.drive.p)
        i_at[n] = c.i_d[best], c.i_q[best]
    return T_e_max, T_sh_max, P_fe_at, i_at


def least_current_points(c: Candidates, w_m, torques):
    """For each shaft torque: the feasible current of least magnitude producing it at speed w_m.

    Exhaustive over the rays: along every ray the current magnitude giving the torque exactly
    is interpolated (the torque rises along a ray), the voltage limit is checked there, and the
    ray with the smallest feasible magnitude wins. Returns dict of arrays (NaN: not reachable).
    """
    n_ray, n_r = c.i_d.shape
    T_sh = c.shaft_torque(c.psi_mag, c.T_e, w_m)
    T_sh = np.maximum.accumulate(T_sh, axis=1)  # guard: non-decreasing along each ray
    span = np.ptp(T_sh) + 1.0 + np.ptp(torques)
    off = (np.arange(n_ray) * span)[:, None]
    keys = (T_sh + off).ravel()  # globally sorted: ray by ray, torque rising along each ray
    q = (torques[None, :] + off)  # [ray, torque]
    k = np.searchsorted(keys, q.ravel(), side="left").reshape(q.shape)
    ray = np.arange(n_ray)[:, None]
    inside = (k > ray * n_r) & (k < (ray + 1) * n_r)  # reached on this ray within I_max
    k = np.clip(k, 1, keys.size - 1)
    lo, hi = k - 1, k
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.clip((q.ravel().reshape(q.shape) - keys[lo]) / (keys[hi] - keys[lo]), 0.0, 1.0)
    lerp = lambda x: x.ravel()[lo] + a * (x.ravel()[hi] - x.ravel()[lo])  # noqa: E731
    i_d, i_q, psi_d, psi_q = lerp(c.i_d), lerp(c.i_q), lerp(c.psi_d), lerp(c.psi_q)
    i_mag = np.hypot(i_d, i_q)
    ok = inside & c.voltage_ok(i_d, i_q, psi_d, psi_q, w_m)
    best = np.argmin(np.where(ok, i_mag, np.inf), axis=0)  # per torque
    cols = np.arange(len(torques))
    found = ok[best, cols]
    pick = lambda x: np.where(found, x[best, cols], np.nan)  # noqa: E731
    return {"i_d": pick(i_d), "i_q": pick(i_q), "psi_d": pick(psi_d), "psi_q": pick(psi_q), "i_mag": pick(i_mag)}


def efficiency_map(c: Candidates, speeds, torques):
    """Efficiency, copper and iron loss over shaft torque x speed at the least-current points."""
    shape = (len(torques), len(speeds))
    eta, P_cu, P_fe = (np.full(shape, np.nan) for _ in range(3))
    dr = c.drive
    for n, w in enumerate(speeds):
        pt = least_current_points(c, w, torques)
        P_cu[:, n] = 1.5 * dr.R_s * pt["i_mag"] ** 2
        P_fe[:, n] = dr.fe.loss_at_speed(np.hypot(pt["psi_d"], pt["psi_q"]), w, dr.p)
        P_out = torques * w
        eta[:, n] = P_out / (P_out + P_fe[:, n] + P_cu[:, n])
    return eta, P_cu, P_fe


def map_properties(dr: Drive) -> dict:
    """Saturation figures read off the map (splines on the CSV grid)."""
    I = dr.I_max
    psi_m = float(dr.psi(0.0, 0.0)[0])
    L_dd0 = float(dr.psi(0.0, 0.0, dx=1)[0])
    L_qq0 = float(dr.psi(0.0, 0.0, dy=1)[1])
    psi_q_I = float(dr.psi(0.0, I)[1])
    L_qq_I = float(dr.psi(0.0, I, dy=1)[1])
    psi_d_I = float(dr.psi(0.0, I)[0])
    # characteristic current: psi_d(i_d, 0) = 0
    i_d = np.linspace(dr.map.i_d[0], 0.0, 200001)
    psi_d0 = dr.psi(i_d, np.zeros_like(i_d))[0]
    i_ch = float(-i_d[np.argmin(np.abs(psi_d0))])
    return {
        "psi_m_Wb": psi_m,
        "L_d_incremental_at_0_mH": L_dd0 * 1e3,
        "L_q_incremental_at_0_mH": L_qq0 * 1e3,
        "L_q_secant_at_I_max_mH": psi_q_I / I * 1e3,
        "L_q_secant_ratio": psi_q_I / I / L_qq0,
        "L_q_incremental_at_I_max_mH": L_qq_I * 1e3,
        "L_q_incremental_ratio": L_qq_I / L_qq0,
        "psi_d_at_iq_I_max_Wb": psi_d_I,
        "cross_saturation_drop_percent": (1 - psi_d_I / psi_m) * 100,
        "psi_m_over_L_d0_A": psi_m / L_dd0,
        "characteristic_current_A": i_ch,
    }


def compute(csv_path=DEFAULT_MAP, plots_dir=None, json_path=None, verbose=True):
    dr = Drive(csv_path)
    c = Candidates(dr)
    speeds = np.linspace(25.0, dr.w_m_max * RPM, 480) / RPM  # rad/s, 25 r/min steps
    T_e_max, T_sh_max, P_fe_env, i_env = envelope(c, speeds)
    P_sh = T_sh_max * speeds
    T_pk = float(np.nanmax(T_e_max))
    # base speed: the last speed at which the peak torque (within 0.5 %) is still available
    base = speeds[np.flatnonzero(T_e_max >= 0.995 * T_pk)[-1]]
    k_pk = int(np.nanargmax(P_sh))
    top = -1
    # iron loss at top speed: at the maximum-torque point (envelope) and at zero shaft torque
    idle = least_current_points(c, speeds[top], np.array([0.0]))
    P_fe_idle = dr.fe.loss_at_speed(np.hypot(idle["psi_d"][0], idle["psi_q"][0]), speeds[top], dr.p)
    # efficiency map
    sp_map = np.linspace(100.0, dr.w_m_max * RPM, 120) / RPM
    tq_map = np.arange(2.0, np.ceil(np.nanmax(T_sh_max)) + 2.0, 2.0)
    eta, _, _ = efficiency_map(c, sp_map, tq_map)
    k_eta = np.unravel_index(np.nanargmax(eta), eta.shape)
    res = {
        "conditions": {
            "u_dc_V": dr.u_dc, "k_u": dr.k_u, "V_max_V": dr.V_max, "I_max_A": dr.I_max, "R_s_ohm": dr.R_s,
            "pole_pairs": dr.p, "temperatures": "map reference (T_winding_ref_K, T_magnet_ref_K)",
            "method": "exhaustive search over the current angle (0.05 deg) and magnitude (1 A, interpolated "
                      "along each ray) on the bicubic-spline map; envelope in 25 r/min steps",
        },
        "map": map_properties(dr),
        "peak_torque_Nm": T_pk,
        "peak_shaft_torque_Nm": float(np.nanmax(T_sh_max)),
        "current_at_peak_torque_A": [float(x) for x in i_env[0]],
        "base_speed_rpm": float(base * RPM),
        "peak_shaft_power_kW": float(P_sh[k_pk] / 1e3),
        "peak_power_speed_rpm": float(speeds[k_pk] * RPM),
        "peak_em_power_kW": float(np.nanmax(T_e_max * speeds) / 1e3),
        "max_speed_rpm": float(speeds[top] * RPM),
        "torque_at_max_speed_Nm": float(T_e_max[top]),
        "shaft_power_at_max_speed_kW": float(P_sh[top] / 1e3),
        "current_at_max_speed_A": [float(x) for x in i_env[top]],
        "iron_loss_at_max_speed_full_torque_W": float(P_fe_env[top]),
        "iron_loss_at_max_speed_no_load_W": float(P_fe_idle),
        "current_at_max_speed_no_load_A": [float(idle["i_d"][0]), float(idle["i_q"][0])],
        "copper_loss_at_I_max_W": float(1.5 * dr.R_s * dr.I_max**2),
        "max_efficiency_percent": float(eta[k_eta] * 100),
        "max_efficiency_at": {"torque_Nm": float(tq_map[k_eta[0]]), "speed_rpm": float(sp_map[k_eta[1]] * RPM)},
    }
    if verbose:
        _print(res)
    if json_path is not None:
        Path(json_path).parent.mkdir(parents=True, exist_ok=True)
        Path(json_path).write_text(json.dumps(_rounded(res), indent=2) + "\n")
    if json_path is not None:
        # The efficiency map as data, for the drive-cycle plots (scenarios/runs/plots.py): rows = torque.
        grid = {"speed_rpm": [round(float(x), 3) for x in sp_map * RPM], "torque_Nm": [float(x) for x in tq_map],
                "efficiency": [[None if not np.isfinite(e) else round(float(e), 5) for e in row] for row in eta],
                "conditions": res["conditions"]}
        (Path(json_path).parent / "efficiency_map.json").write_text(json.dumps(grid) + "\n")
    if plots_dir is not None:
        _plot(dr, speeds, T_e_max, T_sh_max, sp_map, tq_map, eta, base, k_pk, Path(plots_dir))
    return res


def _rounded(x, digits=6):
    """Floats to `digits` significant digits, for a readable JSON."""
    if isinstance(x, dict):
        return {k: _rounded(v, digits) for k, v in x.items()}
    if isinstance(x, list):
        return [_rounded(v, digits) for v in x]
    if isinstance(x, float):
        return float(f"{x:.{digits}g}")
    return x


def _print(r):
    m = r["map"]
    c = r["conditions"]
    print(f"Default motor at u_dc = {c['u_dc_V']:g} V (V_max = {c['V_max_V']:.1f} V), I_max = {c['I_max_A']:g} A, "
          f"R_s = {c['R_s_ohm'] * 1e3:g} mOhm, reference temperatures")
    rows = [
        ("peak torque (electromagnetic)", f"{r['peak_torque_Nm']:.1f} N.m", ">= 250 N.m"),
        ("peak shaft torque", f"{r['peak_shaft_torque_Nm']:.1f} N.m", ""),
        ("base speed", f"{r['base_speed_rpm']:.0f} r/min", ""),
        ("peak shaft power", f"{r['peak_shaft_power_kW']:.1f} kW at {r['peak_power_speed_rpm']:.0f} r/min",
         ">= 100 kW"),
        ("max speed", f"{r['max_speed_rpm']:.0f} r/min, {r['torque_at_max_speed_Nm']:.1f} N.m, "
                      f"{r['shaft_power_at_max_speed_kW']:.1f} kW", "12000 r/min, T > 0"),
        ("psi_m", f"{m['psi_m_Wb'] * 1e3:.2f} mWb", ""),
        ("L_d, L_q at i = 0 (incremental)",
         f"{m['L_d_incremental_at_0_mH']:.3f} mH, {m['L_q_incremental_at_0_mH']:.3f} mH", ""),
        ("L_q at (0, I_max), secant / L_q0",
         f"{m['L_q_secant_at_I_max_mH']:.3f} mH = {m['L_q_secant_ratio'] * 100:.1f} %",
         "<= 60 %"),
        ("L_q at (0, I_max), incremental / L_q0", f"{m['L_q_incremental_at_I_max_mH']:.3f} mH = "
                                                  f"{m['L_q_incremental_ratio'] * 100:.1f} %", ""),
        ("psi_d drop at i_q = I_max", f"{m['cross_saturation_drop_percent']:.1f} %", ">= 8 %"),
        ("psi_m / L_d0", f"{m['psi_m_over_L_d0_A']:.0f} A", f"< {c['I_max_A']:g} A"),
        ("characteristic current (psi_d = 0)", f"{m['characteristic_current_A']:.0f} A", f"< {c['I_max_A']:g} A"),
        ("iron loss at max speed, full torque", f"{r['iron_loss_at_max_speed_full_torque_W']:.0f} W", "few 100 W-2 kW"),
        ("iron loss at max speed, no load", f"{r['iron_loss_at_max_speed_no_load_W']:.0f} W", ""),
        ("copper loss at I_max", f"{r['copper_loss_at_I_max_W']:.0f} W", ""),
        ("max efficiency", f"{r['max_efficiency_percent']:.2f} % at {r['max_efficiency_at']['torque_Nm']:.0f} N.m, "
                           f"{r['max_efficiency_at']['speed_rpm']:.0f} r/min", ""),
    ]
    w = max(len(a) for a, _, _ in rows)
    for a, b, t in rows:
        print(f"  {a:<{w}}  {b:<40} {('target ' + t) if t else ''}")


def _plot(dr, speeds, T_e_max, T_sh_max, sp_map, tq_map, eta, base, k_pk, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    n = speeds * RPM
    title = (f"Default IPMSM, u_dc = {dr.u_dc:g} V (V_max = {dr.V_max:.0f} V peak phase), "
             f"I_max = {dr.I_max:g} A peak, 20 °C")
    # torque-speed envelope
    fig, ax = plt.subplots(figsize=(8, 5), constrained_layout=True)
    ax.plot(n, T_e_max, color="C0", lw=2, label="max. electromagnetic torque $T_e$")
    ax.plot(n, T_sh_max, color="C0", lw=1, ls="--", label="max. shaft torque ($T_e$ less iron-loss drag)")
    ax.axvline(base * RPM, color="0.6", lw=0.8, ls=":")
    ax.annotate(f"base speed {base * RPM:.0f} r/min", (base * RPM, np.nanmax(T_e_max) * 0.45), rotation=90,
                ha="right", va="center", fontsize=8, color="0.4")
    ax.set_xlabel("speed (r/min)")
    ax.set_ylabel("torque (N·m)", color="C0")
    ax.set_xlim(0, n[-1] * 1.02)
    ax.set_ylim(0, np.nanmax(T_e_max) * 1.12)
    ax.grid(alpha=0.3)
    ax2 = ax.twinx()
    ax2.plot(n, T_sh_max * speeds / 1e3, color="C3", lw=2, label="max. shaft power")
    ax2.plot(n[k_pk], T_sh_max[k_pk] * speeds[k_pk] / 1e3, "o", color="C3")
    ax2.annotate(f"{T_sh_max[k_pk] * speeds[k_pk] / 1e3:.0f} kW", (n[k_pk], T_sh_max[k_pk] * speeds[k_pk] / 1e3),
                 xytext=(0, 8), textcoords="offset points", ha="center", color="C3")
    ax2.set_ylabel("power (kW)", color="C3")
    ax2.set_ylim(0, np.nanmax(T_sh_max * speeds) / 1e3 * 1.25)
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, loc="lower right", fontsize=9, framealpha=0.95)
    ax.set_title(title, fontsize=10)
    fig.savefig(out / "torque_speed_envelope.png", dpi=120)
    plt.close(fig)
    # efficiency map
    fig, ax = plt.subplots(figsize=(8, 5.5), constrained_layout=True)
    levels = [70, 80, 85, 88, 90, 92, 93, 94, 95, 96, 96.5]
    e = eta * 100
    cf = ax.contourf(sp_map * RPM, tq_map, e, levels=[50] + levels + [100], cmap="viridis")
    cs = ax.contour(sp_map * RPM, tq_map, e, levels=levels, colors="k", linewidths=0.6)
    ax.clabel(cs, fmt="%g %%", fontsize=8)
    ax.plot(n, T_sh_max, color="C3", lw=2, label="torque envelope (shaft)")
    for P in (25, 50, 75, 100):
        nn = np.linspace(max(P * 1e3 / np.nanmax(T_sh_max) * RPM, 300), n[-1], 200)
        ax.plot(nn, P * 1e3 / (nn / RPM), color="w", lw=0.7, ls="--")
        ax.annotate(f"{P} kW", (nn[-1], P * 1e3 / (nn[-1] / RPM)), xytext=(2, 0), textcoords="offset points",
                    fontsize=7, color="0.3", va="center")
    cb = fig.colorbar(cf, ax=ax, label="efficiency (%)", spacing="uniform")
    cb.set_ticks([50] + levels + [100], labels=[f"{v:g}" for v in [50] + levels + [100]])
    ax.set_xlabel("speed (r/min)")
    ax.set_ylabel("shaft torque (N·m)")
    ax.set_xlim(0, n[-1] * 1.06)
    ax.set_ylim(0, np.nanmax(T_sh_max) * 1.05)
    ax.legend(loc="upper right", fontsize=9)
    ax.set_title("Efficiency (copper + iron loss), least-current operation, motoring\n" + title, fontsize=10)
    fig.savefig(out / "efficiency_map.png", dpi=120)
    plt.close(fig)
    # flux-linkage curves (the map itself)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.8), constrained_layout=True)
    i_d = np.linspace(dr.map.i_d[0], dr.map.i_d[-1], 300)
    i_q = np.linspace(0.0, dr.map.i_q[-1], 300)
    for n_, frac in enumerate((0.0, 0.5, 1.0)):
        x = frac * dr.I_max
        a1.plot(i_d, dr.psi(i_d, np.full_like(i_d, x))[0] * 1e3, color=f"C{n_}", label=f"$i_q$ = {x:g} A")
        a2.plot(i_q, dr.psi(np.full_like(i_q, -x), i_q)[1] * 1e3, color=f"C{n_}", label=f"$i_d$ = {-x + 0.0:g} A")
    a1.set_xlabel("$i_d$ (A)")
    a1.set_ylabel(r"$\psi_d$ (mWb)")
    a2.set_xlabel("$i_q$ (A)")
    a2.set_ylabel(r"$\psi_q$ (mWb)")
    for a in (a1, a2):
        a.axhline(0, color="0.5", lw=0.5)
        a.axvline(0, color="0.5", lw=0.5)
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle("Flux linkages of the default IPMSM (20 °C): d axis with cross-saturation, q axis", fontsize=10)
    fig.savefig(out / "flux_linkages.png", dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--csv", type=Path, default=DEFAULT_MAP)
    ap.add_argument("--out-dir", type=Path, default=REPO_ROOT / "docs" / "motor")
    ap.add_argument("--no-plots", action="store_true")
    args = ap.parse_args(argv)
    compute(args.csv, None if args.no_plots else args.out_dir, args.out_dir / "targets.json")
    print(f"wrote {args.out_dir / 'targets.json'}" + ("" if args.no_plots else " and the plots"))


if __name__ == "__main__":
    main()
