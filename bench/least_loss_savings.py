"""The drive loss saved by least-loss control on the default motor (issue 32's table): at each
speed and share of the shaft-torque limit, the controller FMU's least-loss command (objective = 1)
against its least-current command for the same shaft torque (objective = 0 asked for T_e = T + the
drag, iterated), both losses from the contract's formulas (tests/python/least_loss_reference.py).

    .venv/bin/python bench/least_loss_savings.py     # prints a Markdown table
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "python"))

from brute_force import Drive  # noqa: E402
from least_loss_reference import LossDrive, LossParams, max_shaft_torque  # noqa: E402

from scenarios.cosim.fmu import Fmu  # noqa: E402
from scenarios.maps.flux_map import DEFAULT_MAP, read_flux_map  # noqa: E402

FMU = ROOT / "build" / "fmu" / "IpmsmController.fmu"
H = 1e-4


def command(fmu_params: dict, op: dict) -> tuple[float, float]:
    with Fmu(FMU, **fmu_params) as c:
        c.set(**op)
        c.step(0.0, H)
        i_d, i_q = c.get("i_d_ref", "i_q_ref")
    return float(i_d), float(i_q)


def main() -> int:
    fmap = read_flux_map(DEFAULT_MAP)
    lp = LossParams()
    u_dc, I_max, R_s, p = 355.0, 500.0, 0.012, 4
    rows = []
    for rpm in (2000, 4000, 6000, 8000):
        w = rpm * math.pi / 30
        op = dict(w_m=w, u_dc=u_dc, T_magnet=293.15)
        L = LossDrive(Drive(fmap, p, R_s, I_max, 0.95 * u_dc / math.sqrt(3), p * w), w, u_dc, lp)
        T_max = max_shaft_torque(L, 1.0)
        cells = []
        for frac in (0.05, 0.15, 0.30, 0.60):
            T = frac * T_max
            ll = command(dict(objective=1), dict(op, T_ref=T))
            T_e = T
            for _ in range(8):
                lc = command({}, dict(op, T_ref=T_e))
                T_e += T - float(L.shaft(*lc))
            P_ll, P_lc = float(L.total(*ll)), float(L.total(*lc))
            cells.append(f"+{100 * (P_lc / P_ll - 1):.1f} % ({P_lc - P_ll:.0f} W)")
        rows.append(f"| {rpm} | " + " | ".join(cells) + " |")
    print("| r/min | 5 % T_max | 15 % | 30 % | 60 % |\n|---|---|---|---|---|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
