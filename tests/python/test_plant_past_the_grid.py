"""The plant beyond its flux map's grid (issue 23): open-loop voltage steps whose flux linkages go
50 % past a saturated map's grid run (before: "no finite currents ... the flux map and its
continuation cannot invert" at 25 %), with one warning, the plant's energy integrals balancing:
E_elec = E_cu + 1.5 integral of i . dpsi at standstill (the magnetic term from the recorded
trajectory, trapezoid on 5 us steps)."""
from __future__ import annotations

import numpy as np
import pytest

from scenarios.flux_map import read_flux_map

WARNING = 1


@pytest.fixture(scope="module")
def saturated(tmp_path_factory):
    from tools.saturating_map import SaturatingMachine, write_map
    m = SaturatingMachine(I_s_ratio=0.2, cross=0.1)
    path = tmp_path_factory.mktemp("past") / "map.csv"
    write_map(path, m)
    return m, path, read_flux_map(path)


@pytest.mark.parametrize("axis", ["q", "d", "both"])
def test_voltage_steps_50_percent_past_the_grid(fmu_instances, saturated, axis):
    m, path, fm = saturated
    psi_q_edge = np.abs(fm.psi_q).max()
    psi_d_edge = fm.psi_d.max()
    inst = fmu_instances("IpmsmPlant", logging_on=True)
    inst.init(flux_map=str(path), pole_pairs=m.pole_pairs, R_s=m.R_s, I_max=m.I_max)
    h, u = 5e-6, 400.0
    u_d, u_q = {"q": (0.0, u), "d": (u, 0.0), "both": (u, u)}[axis]
    names = ("psi_d", "psi_q", "i_d", "i_q")
    rows = [inst.get(*names)]
    E0 = inst.get("E_elec", "E_cu")
    inst.set(u_d=u_d, u_q=u_q)
    target = {"q": lambda p: p[1] >= 1.5 * psi_q_edge, "d": lambda p: p[0] >= 1.5 * psi_d_edge,
              "both": lambda p: p[1] >= 1.5 * psi_q_edge and p[0] >= 1.5 * psi_d_edge}[axis]
    for _ in range(20000):
        assert inst.step(h) in (0, WARNING), inst.log.text()
        rows.append(inst.get(*names))
        if target(rows[-1]):
            break
    r = np.array(rows)
    assert target(r[-1]), f"not reached: psi = {r[-1, :2]}, edges {psi_d_edge}, {psi_q_edge}"
    assert np.all(np.isfinite(r))
    warnings = [msg for s, _, msg in inst.log.records if s == WARNING and "legal box" in msg]
    assert len(warnings) == 1, inst.log.text()
    E_elec, E_cu = (a - b for a, b in zip(inst.get("E_elec", "E_cu"), E0))
    i, dpsi = r[:, 2:4], np.diff(r[:, :2], axis=0)
    W = 1.5 * np.sum((i[:-1] + i[1:]) / 2 * dpsi)
    residual = E_elec - E_cu - W
    print(f"{axis}: psi {r[-1, :2]} (edges {psi_d_edge:.3f}, {psi_q_edge:.3f} Wb), i {r[-1, 2:]} A, "
          f"E_elec {E_elec:.4g} J, E_cu {E_cu:.4g} J, magnetic {W:.4g} J, residual {residual / E_elec:.2e}")
    assert abs(residual) < 1e-3 * abs(E_elec)
