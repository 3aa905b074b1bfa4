"""The plant beyond its flux map's grid (issue 23): open-loop voltage steps whose flux linkages go
50 % past a saturated map's grid (by half the grid image's half-width, along each axis stepped)
run with one warning, the plant's energy integrals balancing: E_elec = E_cu + 1.5 integral of
i . dpsi at standstill (the magnetic term from the recorded trajectory, trapezoid on 5 us steps).
Before, the steps towards the corners with -d stopped the plant on these cross-saturated maps
(CVODE CV_TOO_MUCH_WORK: the map's tangent continuation folds there)."""
from __future__ import annotations

import numpy as np
import pytest

from scenarios.maps.flux_map import read_flux_map

WARNING = 1
MACHINES = [(0.3, None, 0.15), (0.3, 0.5, 0.15), (0.2, 0.5, 0.1)]  # (I_s / I_max, I_ds / I_max, cross)
STEPS = {"+q": (0, 1), "+d": (1, 0), "-d+q": (-1, 1), "-d-q": (-1, -1)}


@pytest.fixture(scope="module", params=MACHINES, ids=lambda c: f"Is{c[0]}-Ids{c[1]}-x{c[2]}")
def saturated(request, tmp_path_factory):
    from tools.saturating_map import written
    m, path = written(*request.param, tmp_path_factory.mktemp("past"))
    return m, path, read_flux_map(path)


@pytest.mark.parametrize("step", list(STEPS))
def test_voltage_steps_50_percent_past_the_grid(fmu_instances, saturated, step):
    m, path, fm = saturated
    sd, sq = STEPS[step]
    lo, hi = np.array([fm.psi_d.min(), fm.psi_q.min()]), np.array([fm.psi_d.max(), fm.psi_q.max()])
    past = 0.5 * (hi - lo) / 2  # Wb: half the image's half-width beyond its edge
    goal = [None if s == 0 else (hi[a] + past[a] if s > 0 else lo[a] - past[a]) for a, s in enumerate((sd, sq))]

    def reached(psi):
        return all(g is None or (psi[a] >= g if s > 0 else psi[a] <= g) for a, (g, s) in enumerate(zip(goal, (sd, sq))))

    inst = fmu_instances("IpmsmPlant", logging_on=True)
    inst.init(flux_map=str(path), pole_pairs=m.pole_pairs, R_s=m.R_s)
    h, u = 5e-6, 400.0
    names = ("psi_d", "psi_q", "i_d", "i_q")
    rows = [inst.get(*names)]
    E0 = inst.get("E_elec", "E_cu")
    inst.set(u_d=sd * u, u_q=sq * u)
    for _ in range(20000):
        assert inst.step(h) in (0, WARNING), inst.log.text()
        rows.append(inst.get(*names))
        if reached(rows[-1]):
            break
    r = np.array(rows)
    assert reached(r[-1]), f"not reached: psi = {r[-1, :2]}, goal {goal}"
    assert np.all(np.isfinite(r))
    warnings = [msg for s, _, msg in inst.log.records if s == WARNING and "left the flux map's legal box" in msg]
    assert len(warnings) == 1, inst.log.text()
    E_elec, E_cu = (a - b for a, b in zip(inst.get("E_elec", "E_cu"), E0))
    i, dpsi = r[:, 2:4], np.diff(r[:, :2], axis=0)
    W = 1.5 * np.sum((i[:-1] + i[1:]) / 2 * dpsi)
    residual = E_elec - E_cu - W
    print(f"{step}: psi {r[-1, :2]} Wb (image {lo} .. {hi}), i {r[-1, 2:]} A, E_elec {E_elec:.4g} J, "
          f"E_cu {E_cu:.4g} J, magnetic {W:.4g} J, residual {residual / E_elec:.2e} of E_elec")
    assert abs(residual) < 1e-3 * abs(E_elec)
