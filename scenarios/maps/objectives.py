"""`map show`'s two efficiency maps: least current (objective 0, the seed's) and least loss
(objective 1) over shaft torque x speed, motoring, from the IpmsmController FMU's own prediction
of each command's loss (`P_loss_cmd` = P_cu + P_fe + P_inv; docs/spec/INTERFACE.md, "Least-loss
control"), and their difference (docs/least_loss.md, docs/maps.md).

At a shaft torque T and speed w both commands give the same shaft power P_mech = T w, so

    eta = P_mech / (P_mech + P_loss_cmd)

With objective 1 the controller's T_ref is the shaft torque already. With objective 0 it is the
electromagnetic torque T_e, of which the iron-loss drag P_fe / w is lost before the shaft: T_e is
found by the fixed point T_e = T + P_fe(i(T_e)) / w, P_fe the contract's iron-loss model on the
map's flux at the command's currents (this module's own evaluation of it, through the map's
splines), until T_e moves by less than TORQUE_TOLERANCE_REL.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenarios.cosim.fmu import Fmu
from scenarios.maps.flux_map import FluxMap

#: s, one controller step per question (its default sample time)
STEP = 1e-4
#: the fixed point of objective 0's electromagnetic torque: stop when it moves by less than this
#: (relative): the iron-loss drag is a few per cent of the torque, so it converges in 2-3 steps
TORQUE_TOLERANCE_REL = 1e-9
FIXED_POINT_MAX = 8
#: the controller's parameters `map show` gives both instances (the rest: the FMU's defaults)
MOTOR_PARAMS = ("pole_pairs", "R_s", "I_max", "k_u", "T_magnet_ref", "k_psi_T", "T_winding_ref", "alpha_cu",
                "w_m_max")
IRON_LOSS_PARAMS = ("fe_k_h", "fe_alpha", "fe_k_e", "fe_psi_ref")


@dataclass
class ObjectiveMaps:
    """eta over speeds x torques ([speed, torque]; NaN beyond reach) for each objective, SI."""

    speeds_rad_s: list
    torques_Nm: list               # shaft torques
    eta_least_current: list
    eta_least_loss: list
    P_loss_least_current_W: list
    P_loss_least_loss_W: list

    def difference_pct(self) -> np.ndarray:
        """Efficiency points gained by least loss (percentage points), NaN where either is."""
        return 100.0 * (np.asarray(self.eta_least_loss, float) - np.asarray(self.eta_least_current, float))


def iron_loss(fmap: FluxMap, params: dict, i_d: float, i_q: float, w_m: float) -> float:
    """W, the contract's iron-loss model P_fe = fe_k_h f b^fe_alpha + fe_k_e f^2 b^2 at the map's
    flux (the map's magnet temperature) for the currents (A) at the speed (rad/s)."""
    psi_d, psi_q = fmap.flux(i_d, i_q)
    b = math.hypot(float(psi_d), float(psi_q)) / params["fe_psi_ref"]
    f = params["pole_pairs"] * abs(w_m) / (2.0 * math.pi)
    return params["fe_k_h"] * f * b ** params["fe_alpha"] + params["fe_k_e"] * f * f * b * b


class _Controller:
    """One IpmsmController instance asked one question per step."""

    def __init__(self, fmu_path, csv, params: dict, loss_params: dict, objective: int, u_dc: float,
                 T_magnet: float, T_winding: float):
        cp = {k: params[k] for k in MOTOR_PARAMS if k in params}
        self.fmu = Fmu(fmu_path, instance_name=f"objective{objective}", flux_map=str(csv), method=1, recursion=2,
                       objective=objective, **cp, **loss_params)
        self.inputs = dict(u_dc=u_dc, T_magnet=T_magnet, T_winding=T_winding, i_d=0.0, i_q=0.0)
        self.k = 0

    def ask(self, T_ref: float, w_m: float):
        """(T_cmd, i_d_ref, i_q_ref, P_loss_cmd) for T_ref at w_m."""
        self.fmu.set(T_ref=T_ref, w_m=w_m, **self.inputs)
        self.fmu.step(self.k * STEP, STEP)
        self.k += 1
        return self.fmu.get("T_cmd", "i_d_ref", "i_q_ref", "P_loss_cmd")

    def close(self):
        self.fmu.close()


def objective_maps(fmu_path, csv, fmap: FluxMap, params: dict, loss_params: dict, u_dc: float, T_magnet: float,
                   speeds, torques, bar=None) -> ObjectiveMaps:
    """Both objectives' efficiency over speeds (rad/s, > 0) x shaft torques (N m, > 0).
    params: the machine's (scenarios.maps.show.machine_parameters); loss_params: the iron loss's
    and the inverter's parameters by the FMUs' names."""
    shape = (len(speeds), len(torques))
    eta0, eta1, P0, P1 = (np.full(shape, np.nan) for _ in range(4))
    T_w = params["T_winding_ref"]
    fe = {**params, **{k: loss_params[k] for k in IRON_LOSS_PARAMS if k in loss_params}}
    c0 = _Controller(fmu_path, csv, params, loss_params, 0, u_dc, T_magnet, T_w)
    try:
        c1 = _Controller(fmu_path, csv, params, loss_params, 1, u_dc, T_magnet, T_w)
        try:
            for a, w in enumerate(speeds):
                for b, T in enumerate(torques):
                    if bar is not None:
                        bar.update()
                    P_mech = T * w
                    T_cmd, _, _, loss = c1.ask(T, w)
                    if T_cmd >= T * (1 - 1e-9) and math.isfinite(loss):
                        eta1[a, b], P1[a, b] = P_mech / (P_mech + loss), loss
                    T_e = T
                    for _ in range(FIXED_POINT_MAX):
                        T_cmd, i_d, i_q, loss = c0.ask(T_e, w)
                        if T_cmd < T_e * (1 - 1e-9):
                            break  # beyond reach (objective 0's T_max is electromagnetic)
                        T_next = T + iron_loss(fmap, fe, i_d, i_q, w) / w
                        done = abs(T_next - T_e) <= TORQUE_TOLERANCE_REL * T_next
                        T_e = T_next
                        if done:
                            T_cmd, _, _, loss = c0.ask(T_e, w)
                            if T_cmd >= T_e * (1 - 1e-9) and math.isfinite(loss):
                                eta0[a, b], P0[a, b] = P_mech / (P_mech + loss), loss
                            break
        finally:
            c1.close()
    finally:
        c0.close()
    return ObjectiveMaps([float(x) for x in speeds], [float(x) for x in torques], eta0.tolist(), eta1.tolist(),
                         P0.tolist(), P1.tolist())


def plot_objectives(png, m: ObjectiveMaps, title: str) -> None:
    """objectives.png: least current's and least loss's efficiency and their difference."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rpm = np.asarray(m.speeds_rad_s) * 30.0 / math.pi
    W, T = np.meshgrid(rpm, m.torques_Nm, indexing="ij")
    e0, e1 = (100.0 * np.asarray(x, float) for x in (m.eta_least_current, m.eta_least_loss))
    d = m.difference_pct()
    fig, ax = plt.subplots(1, 3, figsize=(18, 5.2))
    finite = np.isfinite(np.concatenate([e0.ravel(), e1.ravel()]))
    lo = float(np.nanpercentile(np.concatenate([e0.ravel(), e1.ravel()])[finite], 2)) if finite.any() else 80.0
    levels = np.linspace(lo, max(lo + 1.0, float(np.nanmax(np.concatenate([e0.ravel(), e1.ravel()]))) if finite.any()
                             else 100.0), 21)
    for a, e, name in ((ax[0], e0, "least current (objective 0)"), (ax[1], e1, "least loss (objective 1)")):
        if np.isfinite(e).any():
            cs = a.contourf(W, T, np.clip(e, levels[0], None), levels=levels, cmap="viridis")
            fig.colorbar(cs, ax=a, label="efficiency, motor + inverter (%)")
        a.set(title=name, xlabel="speed (r/min)", ylabel="shaft torque (N m)")
    if np.isfinite(d).any():
        top = max(float(np.nanmax(np.abs(d))), 1e-3)
        cs = ax[2].contourf(W, T, d, levels=np.linspace(-top, top, 21), cmap="RdBu_r")
        fig.colorbar(cs, ax=ax[2], label="least loss - least current (efficiency points, %)")
    ax[2].set(title="difference", xlabel="speed (r/min)", ylabel="shaft torque (N m)")
    fig.suptitle(f"{title}: eta = P_mech / (P_mech + P_loss_cmd), the controller's predicted loss", fontsize=10)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)
