"""The default motor's flux map (fmu_src/resources/ev_ipmsm_default.csv): format, physics, targets.

Reads the CSV with its own small reader (not the project's), so that it checks the file itself.
"""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from scipy.interpolate import RectBivariateSpline

from scenarios.core.constants import T_REFERENCE_K, U_DC_NOMINAL_V
from scenarios.maps.flux_map import DEFAULT_MAP

CSV = DEFAULT_MAP
RPM = 30 / math.pi

REQUIRED_KEYS = [
    "pole_pairs", "R_s_ohm", "T_winding_ref_K", "alpha_cu_per_K", "T_magnet_ref_K", "k_psi_T_per_K",
    "I_max_A", "u_dc_V", "k_u", "w_m_max_rad_s",
    "fe_k_h_W_per_Hz", "fe_alpha", "fe_k_e_W_per_Hz2", "fe_psi_ref_Wb",
]


def read_map(text: str):
    """(comment lines, metadata, header, raw rows as strings)."""
    lines = text.splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    meta = {}
    for ln in comments:
        key, sep, value = ln[1:].strip().partition(": ")
        if sep and key.isidentifier():
            meta[key] = value
    body = [ln for ln in lines if ln and not ln.startswith("#")]
    rows = list(csv.reader(body))
    return comments, meta, rows[0], rows[1:]


@pytest.fixture(scope="module")
def fmap():
    comments, meta, header, rows = read_map(CSV.read_text())
    assert header == ["i_d", "i_q", "psi_d", "psi_q"]
    data = np.array(rows, dtype=float)
    i_d, i_q = np.unique(data[:, 0]), np.unique(data[:, 1])
    assert len(data) == len(i_d) * len(i_q), "not a full rectangular grid"
    psi_d = np.full((len(i_d), len(i_q)), np.nan)
    psi_q = psi_d.copy()
    j, k = np.searchsorted(i_d, data[:, 0]), np.searchsorted(i_q, data[:, 1])
    psi_d[j, k], psi_q[j, k] = data[:, 2], data[:, 3]
    assert np.isfinite(psi_d).all() and np.isfinite(psi_q).all(), "duplicate or missing grid points"
    return {"i_d": i_d, "i_q": i_q, "psi_d": psi_d, "psi_q": psi_q, "meta": meta, "rows": rows,
            "I_max": float(meta["I_max_A"])}


def at(m, i_d, i_q):
    """Grid value (psi_d, psi_q) at a grid point."""
    j = int(np.flatnonzero(m["i_d"] == i_d)[0])
    k = int(np.flatnonzero(m["i_q"] == i_q)[0])
    return m["psi_d"][j, k], m["psi_q"][j, k]


def test_metadata_and_grid(fmap):
    meta, I = fmap["meta"], fmap["I_max"]
    for key in REQUIRED_KEYS:
        assert key in meta, key
        float(meta[key])
    assert int(meta["pole_pairs"]) == 4
    assert float(meta["alpha_cu_per_K"]) == pytest.approx(0.00393)
    assert float(meta["k_psi_T_per_K"]) == pytest.approx(-0.0012)
    assert I <= 500
    # the scenarios' constants are the default motor's design point (scenarios/core/constants.py)
    assert float(meta["u_dc_V"]) == U_DC_NOMINAL_V
    assert float(meta["T_winding_ref_K"]) == float(meta["T_magnet_ref_K"]) == T_REFERENCE_K
    assert float(meta["w_m_max_rad_s"]) * RPM == pytest.approx(12000, rel=1e-6)
    assert 0.010 <= float(meta["R_s_ohm"]) <= 0.020
    i_d, i_q = fmap["i_d"], fmap["i_q"]
    assert i_d[0] <= -1.4 * I and i_d[-1] >= 0.6 * I
    assert i_q[0] <= -1.4 * I and i_q[-1] >= 1.4 * I
    assert np.diff(i_d).max() <= 20 and np.diff(i_q).max() <= 20
    assert 0 in i_d and 0 in i_q and I in i_q and -I in i_d
    # at least 9 significant digits in the flux values (all but the odd short exact value)
    digits = [len(s.lower().split("e")[0].replace("-", "").replace(".", "").strip("0"))
              for row in fmap["rows"] for s in row[2:] if float(s) != 0]
    assert np.mean(np.array(digits) >= 9) > 0.95


def test_monotonic(fmap):
    assert (np.diff(fmap["psi_d"], axis=0) > 0).all(), "psi_d must increase with i_d"
    assert (np.diff(fmap["psi_q"], axis=1) > 0).all(), "psi_q must increase with i_q"


def reciprocity_error(m):
    """|dpsi_d/di_q - dpsi_q/di_d| / sqrt(L_dd L_qq) at interior points (central differences)."""
    hd, hq = np.diff(m["i_d"])[0], np.diff(m["i_q"])[0]
    pd, pq = m["psi_d"], m["psi_q"]
    L_dq = (pd[1:-1, 2:] - pd[1:-1, :-2]) / (2 * hq)
    L_qd = (pq[2:, 1:-1] - pq[:-2, 1:-1]) / (2 * hd)
    L_dd = (pd[2:, 1:-1] - pd[:-2, 1:-1]) / (2 * hd)
    L_qq = (pq[1:-1, 2:] - pq[1:-1, :-2]) / (2 * hq)
    return np.abs(L_dq - L_qd) / np.sqrt(L_dd * L_qq)


def test_reciprocity(fmap):
    # The model is exactly reciprocal; on the 20 A grid the O(h^2) truncation error of the two
    # central differences is ~0.1 % of the self inductances. A measured map (the shared Baldor
    # PM-SyRM one) shows ~3 %.
    assert reciprocity_error(fmap).max() < 5e-3
    # the check is not vacuous: a 2 % non-reciprocal cross term is caught
    bad = dict(fmap)
    d, q = np.meshgrid(fmap["i_d"], fmap["i_q"], indexing="ij")
    bad["psi_d"] = fmap["psi_d"] + 0.02 * 0.3e-3 * d * q / fmap["I_max"]
    assert reciprocity_error(bad).max() > 5e-3


def test_odd_even_in_i_q(fmap):
    assert np.array_equal(fmap["psi_q"], -fmap["psi_q"][:, ::-1])
    assert np.array_equal(fmap["psi_d"], fmap["psi_d"][:, ::-1])


def test_saturation_targets(fmap):
    I = fmap["I_max"]
    h = np.diff(fmap["i_q"])[0]
    psi_m, _ = at(fmap, 0, 0)
    assert 0.06 <= psi_m <= 0.09
    L_q0 = (at(fmap, 0, h)[1] - at(fmap, 0, -h)[1]) / (2 * h)
    L_d0 = (at(fmap, h, 0)[0] - at(fmap, -h, 0)[0]) / (2 * h)
    assert 0.15e-3 <= L_d0 <= 0.3e-3 and 0.4e-3 <= L_q0 <= 0.8e-3
    psi_d_I, psi_q_I = at(fmap, 0, I)
    assert psi_q_I / I <= 0.60 * L_q0, "q-axis saturation: secant L_q at I_max <= 60 % of unsaturated"
    assert psi_d_I <= 0.92 * psi_m, "cross-saturation: psi_d at i_q = I_max at least 8 % below psi_m"
    assert psi_m / L_d0 < I, "field weakening to any speed needs psi_m / L_d < I_max"
    assert at(fmap, -I, 0)[0] < 0, "psi_d(i_d, 0) crosses zero within I_max"


class CoarseDrive:
    """Coarse brute force: all currents on a 4 A grid of the quarter disc, spline-interpolated map."""

    def __init__(self, m):
        meta = {k: float(v) for k, v in m["meta"].items() if k in REQUIRED_KEYS}
        self.p, self.R, self.I = meta["pole_pairs"], meta["R_s_ohm"], meta["I_max_A"]
        self.V = meta["k_u"] * meta["u_dc_V"] / math.sqrt(3)
        self.meta = meta
        d, q = np.meshgrid(np.arange(-self.I, 0.1, 4.0), np.arange(0.0, self.I + 0.1, 4.0), indexing="ij")
        keep = np.hypot(d, q) <= self.I
        self.i_d, self.i_q = d[keep], q[keep]
        sd = RectBivariateSpline(m["i_d"], m["i_q"], m["psi_d"])
        sq = RectBivariateSpline(m["i_d"], m["i_q"], m["psi_q"])
        self.psi_d, self.psi_q = sd.ev(self.i_d, self.i_q), sq.ev(self.i_d, self.i_q)
        self.T = 1.5 * self.p * (self.psi_d * self.i_q - self.psi_q * self.i_d)

    def feasible(self, n_rpm):
        w = self.p * n_rpm / RPM
        v_d = self.R * self.i_d - w * self.psi_q
        v_q = self.R * self.i_q + w * self.psi_d
        return np.hypot(v_d, v_q) <= self.V

    def iron_loss(self, n_rpm):
        f = self.p * n_rpm / 60
        b = np.hypot(self.psi_d, self.psi_q) / self.meta["fe_psi_ref_Wb"]
        hysteresis = self.meta["fe_k_h_W_per_Hz"] * f * b ** self.meta["fe_alpha"]
        return hysteresis + self.meta["fe_k_e_W_per_Hz2"] * f**2 * b**2

    def max_shaft_power(self, n_rpm):
        ok = self.feasible(n_rpm)
        P = self.T * n_rpm / RPM - self.iron_loss(n_rpm)
        return P[ok].max() if ok.any() else -np.inf


@pytest.fixture(scope="module")
def drive(fmap):
    return CoarseDrive(fmap)


def test_peak_torque(drive):
    ok = drive.feasible(1000.0)
    assert drive.T[ok].max() >= 250.0


def test_peak_power(drive):
    assert max(drive.max_shaft_power(n) for n in np.arange(3000.0, 12001.0, 500.0)) >= 100e3


def test_max_speed(drive):
    ok = drive.feasible(12000.0)
    assert ok.any() and drive.T[ok].max() > 20.0


def test_iron_loss_at_top_speed(drive):
    """A few hundred W to ~2 kW at top speed: at full torque and at the least-current idle point."""
    ok = drive.feasible(12000.0)
    P_fe = drive.iron_loss(12000.0)
    full = np.argmax(np.where(ok, drive.T, -np.inf))
    idle = np.argmin(np.where(ok & (drive.T >= 0), np.hypot(drive.i_d, drive.i_q), np.inf))
    for k in (full, idle):
        assert 200.0 <= P_fe[k] <= 2500.0


def test_regenerated_map_matches_shipped():
    from tools.default_motor.make_default_map import csv_text

    c_new, meta_new, h_new, rows_new = read_map(csv_text())
    c_old, meta_old, h_old, rows_old = read_map(CSV.read_text())
    assert c_new == c_old and h_new == h_old
    a, b = np.array(rows_new, dtype=float), np.array(rows_old, dtype=float)
    assert a.shape == b.shape
    np.testing.assert_array_equal(a[:, :2], b[:, :2])
    np.testing.assert_allclose(a[:, 2:], b[:, 2:], rtol=1e-10, atol=1e-13)


def test_model_is_reciprocal_and_convex():
    """The model itself: incremental inductances from the Hessian match finite differences of
    psi(i), and the Hessian is positive definite over the whole map (unique, invertible map)."""
    from tools.default_motor import saturation as sat

    rng = np.random.default_rng(1)
    i_d, i_q = rng.uniform(-700, 300, 200), rng.uniform(-700, 700, 200)
    L_dd, L_dq, L_qq = sat.incremental_inductances(i_d, i_q)
    h = 1e-3
    pdp, pqp = sat.flux_from_current(i_d + h, i_q)
    pdm, pqm = sat.flux_from_current(i_d - h, i_q)
    np.testing.assert_allclose((pdp - pdm) / (2 * h), L_dd, rtol=1e-6)
    np.testing.assert_allclose((pqp - pqm) / (2 * h), L_dq, rtol=1e-5, atol=1e-10)
    pdp, pqp = sat.flux_from_current(i_d, i_q + h)
    pdm, pqm = sat.flux_from_current(i_d, i_q - h)
    np.testing.assert_allclose((pdp - pdm) / (2 * h), L_dq, rtol=1e-5, atol=1e-10)
    np.testing.assert_allclose((pqp - pqm) / (2 * h), L_qq, rtol=1e-6)
    # psi = grad W' (co-energy)
    w_p, w_m = sat.coenergy(i_d + h, i_q), sat.coenergy(i_d - h, i_q)
    np.testing.assert_allclose((w_p - w_m) / (2 * h), sat.flux_from_current(i_d, i_q)[0], rtol=1e-6, atol=1e-9)
    d, q = np.meshgrid(np.arange(-700, 301, 10.0), np.arange(-700, 701, 10.0), indexing="ij")
    H_dd, H_dq, H_qq = sat.flux_hessian(*sat.flux_from_current(d, q))
    assert (H_dd > 0).all() and (H_dd * H_qq - H_dq**2 > 0.5 * H_dd * H_qq).all()
