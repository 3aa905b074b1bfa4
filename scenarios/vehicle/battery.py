"""Traction battery: 96s NMC pack as an equivalent circuit (OCV(SOC), series R0, one RC pair),
driven by a DC power demand and giving the DC-link voltage u_dc.

    u = OCV(SOC) - R0 i - u_RC,    C1 du_RC/dt = i - u_RC / R1,    dSOC/dt = -i / Q

(i > 0 discharges). Within a step the current is held; the RC pair and SOC are then advanced
exactly, and the current solves P = u_avg i with u_avg the terminal voltage averaged over the
step, so that the terminal energy P dt is what the circuit delivers (energy is conserved
step by step, not only as dt -> 0).

Charging is capped so the terminal voltage stays at or below u_cell_max per cell (4.2 V, the
usual NMC upper limit) throughout the step, and SOC at or below 1; what the cap refuses is
reported as curtailed power.
"""
from __future__ import annotations

import csv
import math
from bisect import bisect_right
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator

from scenarios.core.paths import DATA_DIR

#: the package's data/ocv_nmc_cell_and_96s.csv: SOC 0..1 step 0.05, two published cell fits
OCV_CSV = DATA_DIR / "ocv_nmc_cell_and_96s.csv"

#: fit name -> column of the cell OCV (V)
OCV_FITS = {
    "chen2020": "ocv_cell_chen2020_V",                    # LG M50 (NMC811 | graphite-SiOx), Chen et al. 2020
    "pybamm_ecm_example": "ocv_cell_pybamm_ecm_example_V",  # PyBaMM's example ECM cell (BSD-3)
}

#: ocv_fit = "csv": the cell OCV is column OCV_CSV_COLUMN of the user's own ocv_csv (a drive
#: description's battery.ocv = "file.csv", docs/spec/INTERFACE.md)
OCV_CSV_COLUMN = "ocv_cell_V"


@dataclass
class BatteryParams:
    """Pack parameters. Defaults: a 40 kWh (gross) pack like the 2018+ Nissan Leaf's, 192 cells
    as 96s2p; the Chen 2020 OCV fit; R0, R1, tau assumed pack values of that class (no measured
    record of this pack: docs/vehicle.md)."""

    n_series: int = 96                # cells in series (Leaf 40 kWh: 96s2p, 192 cells)
    n_parallel: int = 2
    cell_capacity_Ah: float = 56.3    # Ah per cell (40 kWh / 96 / 2 / ~3.7 V; the Leaf's AESC cell)
    ocv_fit: str = "chen2020"         # measured-electrode fit of a commercial NMC cell (see docs)
    R0: float = 0.038                 # ohm, pack series resistance (assumed; 0.79 mOhm per cell at 96s2p)
    R1: float = 0.058                 # ohm, pack polarisation resistance (assumed)
    tau1: float = 30.0                # s, R1 C1 (assumed)
    u_cell_max: float = 4.2           # V, charge cut-off per cell (NMC | graphite)
    soc0: float = 0.5                 # mean SOC of a full-to-empty test (SAE J1634); 355.7 V with chen2020
    ocv_csv: Path = field(default=OCV_CSV)

    @property
    def capacity_As(self) -> float:
        """Pack charge capacity Q, A s (C)."""
        return self.n_parallel * self.cell_capacity_Ah * 3600.0

    @property
    def C1(self) -> float:
        """Polarisation capacitance, F."""
        return self.tau1 / self.R1

    @property
    def u_max(self) -> float:
        """Terminal-voltage cap while charging, V (403.2 V for 96 x 4.2 V)."""
        return self.n_series * self.u_cell_max


class _ScalarPPoly:
    """Fast scalar evaluation of a scipy PPoly (the step loop needs the OCV at every step;
    scipy's array machinery costs ~10 us a call, this ~1 us)."""

    def __init__(self, pp):
        self.x = pp.x.tolist()
        self.c = pp.c.T.tolist()        # per interval, highest power first
        self.n = len(self.x) - 2        # index of the last interval

    def interval(self, s: float) -> int:
        """Index of the interval holding s (the first or last one beyond the ends)."""
        return min(max(bisect_right(self.x, s) - 1, 0), self.n)

    def on(self, i: int, s: float) -> float:
        """The polynomial of interval i at s (Horner)."""
        d = s - self.x[i]
        acc = 0.0
        for ck in self.c[i]:
            acc = acc * d + ck
        return acc

    def __call__(self, s: float) -> float:
        return self.on(self.interval(s), s)


class Ocv:
    """Pack OCV(SOC), V: the chosen cell column times n_series, a monotone cubic (PCHIP)
    through the 0.05-spaced points (exact at them, no overshoot between), with its derivative
    and antiderivative (for the energy between two SOCs). Scalars in, floats out; SOC outside
    [0, 1] is an error."""

    def __init__(self, p: BatteryParams):
        if p.ocv_fit != "csv" and p.ocv_fit not in OCV_FITS:
            raise ValueError(f"unknown OCV fit {p.ocv_fit!r}: one of {', '.join(OCV_FITS)}, or 'csv'")
        col = OCV_CSV_COLUMN if p.ocv_fit == "csv" else OCV_FITS[p.ocv_fit]
        with open(p.ocv_csv, newline="") as f:
            rows = list(csv.DictReader(f))
        if not rows or "soc" not in rows[0] or col not in rows[0]:
            raise ValueError(f"{p.ocv_csv}: needs columns 'soc' and '{col}'")
        soc = np.array([float(r["soc"]) for r in rows])
        ocv = p.n_series * np.array([float(r[col]) for r in rows])
        if soc[0] != 0.0 or soc[-1] != 1.0 or np.any(np.diff(soc) <= 0) or np.any(np.diff(ocv) <= 0):
            raise ValueError(f"{p.ocv_csv}: SOC must run 0..1 increasing and OCV increase with it")
        self.soc_points, self.ocv_points = soc, ocv
        pp = PchipInterpolator(soc, ocv, extrapolate=False)
        self.pchip = pp
        self._f = _ScalarPPoly(pp)
        self._df = _ScalarPPoly(pp.derivative())
        self._F = _ScalarPPoly(pp.antiderivative())
        assert self._df.x == self._f.x == self._F.x  # at() finds the interval once for the three

    @staticmethod
    def _check(soc: float) -> float:
        if not (-1e-12 <= soc <= 1.0 + 1e-12):
            raise ValueError(f"SOC {soc} outside [0, 1]")
        return min(max(soc, 0.0), 1.0)

    def __call__(self, soc: float) -> float:
        return self._f(self._check(soc))

    def slope(self, soc: float) -> float:
        """dOCV/dSOC, V."""
        return self._df(self._check(soc))

    def integral(self, soc_a: float, soc_b: float) -> float:
        """Integral of OCV dSOC from soc_a to soc_b, V (times Q: the chemical energy, J)."""
        return self._F(self._check(soc_b)) - self._F(self._check(soc_a))

    def at(self, soc: float) -> tuple[float, float, float]:
        """(OCV, dOCV/dSOC, integral of OCV dSOC from 0) at soc: the three values a battery step
        needs, the same numbers as __call__, slope and integral give."""
        s = self._check(soc)
        i = self._f.interval(s)
        return self._f.on(i, s), self._df.on(i, s), self._F.on(i, s)


@dataclass(slots=True)
class BatteryStep:
    """What one step did. Powers at the terminals; positive = discharge."""

    u: float            # V, terminal voltage averaged over the step
    i: float            # A, current held over the step (+ discharge)
    P: float            # W, power delivered (u i); P_demand = P - P_curtailed + P_unmet
    P_curtailed: float  # W >= 0, charging power refused by the 4.2 V/cell cap or a full battery
    P_unmet: float      # W >= 0, discharge power beyond the pack's maximum (E0^2 / 4 R)
    u_end: float        # V, terminal voltage at the end of the step (current still flowing)
    soc: float          # SOC at the end of the step


class Battery:
    """The pack's state (SOC, u_RC) and its energy bookkeeping (J):
    E_terminal = E_ocv - E_loss_R0 - E_loss_R1 - (W_C - W_C0) holds to rounding."""

    def __init__(self, p: BatteryParams | None = None, soc0: float | None = None):
        p = p if p is not None else BatteryParams()
        self.p = p
        self.Q = p.capacity_As          # A s, charge capacity (derived from p once: used at every step)
        self.u_max = p.u_max            # V, terminal-voltage cap while charging
        self.ocv_fn = Ocv(p)
        self.soc = float(p.soc0 if soc0 is None else soc0)
        self.ocv_fn._check(self.soc)
        self.u_rc = 0.0
        self._cache = None
        self._ocv_at = (None, None)     # (SOC, Ocv.at(SOC)) of the last SOC asked for
        self.u = self.ocv()             # last terminal voltage (open circuit at the start)
        self.E_terminal = 0.0           # integral of u i dt
        self.E_ocv = 0.0                # Q times integral of OCV dSOC released
        self.E_loss_R0 = 0.0
        self.E_loss_R1 = 0.0
        self.E_curtailed = 0.0          # integral of P_curtailed dt
        self.E_unmet = 0.0

    # -- circuit quantities ---------------------------------------------------------------
    def ocv(self, soc: float | None = None) -> float:
        return self.ocv_fn(soc) if soc is not None else self._ocv_now()[0]

    def _ocv_now(self) -> tuple[float, float, float]:
        """Ocv.at(self.soc), evaluated once per SOC: a step needs the OCV, its slope and its
        integral at the SOC it starts from, which is where the last one ended."""
        soc, at = self._ocv_at
        if soc != self.soc:
            at = self.ocv_fn.at(self.soc)
            self._ocv_at = (self.soc, at)
        return at

    @property
    def W_C(self) -> float:
        """Energy stored in the polarisation capacitor, J."""
        return 0.5 * self.p.C1 * self.u_rc ** 2

    def _coeffs(self, dt: float):
        """Step-average terminal voltage as u_avg(i) = E0 - R_eff i (current held over dt),
        and the end-of-step voltage as u_end(i) = E1 - R_end i (OCV linearised over the step's
        tiny SOC change: 10 ms at 300 A is 1e-5 of the charge)."""
        key = (self.soc, self.u_rc, dt)
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1]
        p = self.p
        e = math.exp(-dt / p.tau1)
        a = p.tau1 / dt * (1.0 - e)      # mean of exp(-t/tau) over the step
        ocv, docv, _ = self._ocv_now()
        k = docv * dt / self.Q           # OCV change per ampere over the step
        E0 = ocv - a * self.u_rc
        R_eff = p.R0 + (1.0 - a) * p.R1 + 0.5 * k
        E1 = ocv - e * self.u_rc
        R_end = p.R0 + (1.0 - e) * p.R1 + k
        self._cache = (key, (E0, R_eff, E1, R_end, ocv))
        return E0, R_eff, E1, R_end, ocv

    def max_charge_current(self, dt: float) -> float:
        """Most negative current (A, <= 0) allowed over the next step: terminal voltage at or
        below u_max at its start and end (in between it moves monotonically), SOC <= 1."""
        p = self.p
        E0, R_eff, E1, R_end, ocv = self._coeffs(dt)
        i_start = (ocv - self.u_rc - self.u_max) / p.R0
        i_end = (E1 - self.u_max) / R_end
        i_full = -(1.0 - self.soc) * self.Q / dt
        return min(0.0, max(i_start, i_end, i_full))

    def max_charge_power(self, dt: float) -> float:
        """Largest charging power (W, >= 0) the terminals accept over the next step."""
        E0, R_eff, *_ = self._coeffs(dt)
        i = self.max_charge_current(dt)
        return -(E0 - R_eff * i) * i

    def max_discharge_power(self, dt: float) -> float:
        """Matched-load maximum E0^2 / (4 R_eff), W; no current limit is modelled."""
        E0, R_eff, *_ = self._coeffs(dt)
        return E0 * E0 / (4.0 * R_eff)

    # -- one step ---------------------------------------------------------------------------
    def step(self, P_demand: float, dt: float) -> BatteryStep:
        """Deliver P_demand (W, + discharge, - charge) at the terminals for dt seconds."""
        if not math.isfinite(P_demand) or dt <= 0:
            raise ValueError(f"bad step: P = {P_demand} W, dt = {dt} s")
        p = self.p
        E0, R_eff, E1, R_end, _ = self._coeffs(dt)
        F_start = self._ocv_now()[2]
        P_max = E0 * E0 / (4.0 * R_eff)
        P_unmet = 0.0
        if P_demand > P_max:
            P_unmet = P_demand - P_max
            i = E0 / (2.0 * R_eff)
        else:
            # the smaller root of R_eff i^2 - E0 i + P = 0: the branch through i = 0 at P = 0
            disc = E0 * E0 - 4.0 * R_eff * P_demand
            i = 2.0 * P_demand / (E0 + math.sqrt(disc))
        capped = False
        if i < 0.0:
            i_min = self.max_charge_current(dt)
            if i < i_min:
                i, capped = i_min, True
        u = E0 - R_eff * i
        P = u * i
        P_curtailed = P - P_demand if capped else 0.0   # P is monotone in i, so P > P_demand here

        soc_next = self.soc - i * dt / self.Q
        if soc_next < 0.0:
            raise RuntimeError(f"battery empty: SOC would fall to {soc_next:.4g}")
        soc_next = min(soc_next, 1.0)
        # exact RC response to the held current, and its resistive loss over the step
        e = math.exp(-dt / p.tau1)
        c, d = p.R1 * i, self.u_rc - p.R1 * i
        u_rc_next = c + d * e
        E_R1 = (c * c * dt + 2 * c * d * p.tau1 * (1 - e) + d * d * p.tau1 / 2 * (1 - e * e)) / p.R1

        self.E_terminal += P * dt
        self.E_loss_R0 += p.R0 * i * i * dt
        self.E_loss_R1 += E_R1
        self.E_curtailed += P_curtailed * dt
        self.E_unmet += P_unmet * dt
        self.soc = soc_next
        self.u_rc = u_rc_next
        ocv_end, _, F_end = self._ocv_now()
        self.E_ocv += self.Q * (F_start - F_end)  # Q times the integral of OCV dSOC released
        u_end = ocv_end - p.R0 * i - self.u_rc
        self.u = u_end
        return BatteryStep(u=u, i=i, P=P, P_curtailed=P_curtailed, P_unmet=P_unmet, u_end=u_end, soc=self.soc)

    def energy_residual(self, W_C0: float = 0.0) -> float:
        """E_ocv - losses - change of capacitor energy - E_terminal, J (zero up to the OCV
        linearisation within steps)."""
        return self.E_ocv - self.E_loss_R0 - self.E_loss_R1 - (self.W_C - W_C0) - self.E_terminal
