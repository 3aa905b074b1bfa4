"""Where a flux map is legal, and how noisy it is: the analysis behind `map check` and `map repair`.

A map describes a machine only where currents are a function of the flux linkages: psi_d
rising with i_d along every i_q line and psi_q with i_q along every i_d line (the grid
values), and the incremental inductance matrix d psi / d i with a positive determinant (so the
map does not fold; checked at the nodes, the edges' and the cells' midpoints on the map's
bicubic spline, scenarios.maps.flux_map). This module finds the defects and the largest
rectangle of grid lines free of them that holds a required current box. It does not decide
whether a map is accepted: the FMUs do (scenarios.maps.fmu_verdict), and their verdict is the
one `map check` reports and `map repair` verifies.

Each defect is a box of grid indices [j0, j1] x [k0, k1] (i_d index j, i_q index k): a
sub-grid excludes it when one of its sides passes inside the box.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from scenarios.core.fmu_ranges import operating_region_constant
from scenarios.maps.flux_map import FluxMap

#: the variance of the 4th difference of white noise is C(8, 4) = 70 sigma^2 (Rice, Ann. Stat.
#: 12 (1984) 1215, difference-based variance estimators); a smooth map's 4th differences are small
FOURTH_DIFF_VAR = 70.0
#: the median absolute deviation of a normal variable is 0.6745 sigma
MAD_NORMAL = 0.6745


@dataclass
class Defects:
    """Index boxes (N x 4: j0, j1, k0, k1) of each kind of defect."""

    psi_d_falls: np.ndarray   # psi_d[j + 1, k] <= psi_d[j, k]
    psi_q_falls: np.ndarray   # psi_q[j, k + 1] <= psi_q[j, k]
    folds: np.ndarray         # det(d psi / d i) <= 0 at a node or a midpoint

    def all(self) -> np.ndarray:
        return np.concatenate([self.psi_d_falls, self.psi_q_falls, self.folds])

    def count(self) -> int:
        return len(self.all())


def defects(fmap: FluxMap) -> Defects:
    jd, kd = np.nonzero(np.diff(fmap.psi_d, axis=0) <= 0.0)
    jq, kq = np.nonzero(np.diff(fmap.psi_q, axis=1) <= 0.0)
    folds = []
    # nodes (0), midpoints of edges along i_d (1) and i_q (2), cell centres (3)
    for dj, dk in ((0, 0), (1, 0), (0, 1), (1, 1)):
        x = fmap.i_d if dj == 0 else 0.5 * (fmap.i_d[:-1] + fmap.i_d[1:])
        y = fmap.i_q if dk == 0 else 0.5 * (fmap.i_q[:-1] + fmap.i_q[1:])
        L_dd, L_qd = fmap.flux_on_grid(x, y, dx=1)
        L_dq, L_qq = fmap.flux_on_grid(x, y, dy=1)
        det = L_dd * L_qq - L_dq * L_qd
        # a fold: the determinant at most the FMUs' kFoldRelative of L_dd L_qq (operating_region.hpp)
        j, k = np.nonzero(~(det > operating_region_constant("fold_relative") * np.abs(L_dd * L_qq)))
        folds.append(np.column_stack([j, j + dj, k, k + dk]))
    return Defects(np.column_stack([jd, jd + 1, kd, kd]), np.column_stack([jq, jq, kq, kq + 1]),
                   np.concatenate(folds).astype(int))


def where(fmap: FluxMap, box: np.ndarray) -> tuple[float, float]:
    """The currents (A) at the middle of a defect box."""
    j0, j1, k0, k1 = box
    return 0.5 * float(fmap.i_d[j0] + fmap.i_d[j1]), 0.5 * float(fmap.i_q[k0] + fmap.i_q[k1])


def nearest(fmap: FluxMap, boxes: np.ndarray):
    """The defect nearest zero current: ((i_d, i_q), |i|), or None."""
    if len(boxes) == 0:
        return None
    pts = np.array([where(fmap, b) for b in boxes])
    r = np.hypot(pts[:, 0], pts[:, 1])
    k = int(np.argmin(r))
    return (float(pts[k, 0]), float(pts[k, 1])), float(r[k])


def has_magnet(fmap: FluxMap) -> bool:
    """The FMUs' test (fmu_src/machine/operating_region.hpp): psi_d(0, 0) on the map's spline is
    positive and at least kMagnetFraction of the largest |psi_d| on the grid."""
    psi_m = float(fmap.flux(0.0, 0.0)[0])
    return psi_m > 0.0 and psi_m >= operating_region_constant("magnet_fraction") * float(np.abs(fmap.psi_d).max())


def refused_box(fmap: FluxMap, I_max: float) -> tuple[float, float, float, float]:
    """The FMUs' required box (operating_region.hpp): required_box widened by kOperatingMargin
    I_max on every side and cut to the grid; a defect inside it makes the FMUs refuse the map."""
    m = operating_region_constant("margin") * I_max
    lo_d, hi_d, lo_q, hi_q = required_box(I_max, not has_magnet(fmap))

    def cut(lo, hi, a, b):
        x0 = min(max(lo, a), b)
        return x0, max(min(hi, b), x0)
    return (*cut(lo_d - m, hi_d + m, fmap.i_d[0], fmap.i_d[-1]), *cut(lo_q - m, hi_q + m, fmap.i_q[0], fmap.i_q[-1]))


def required_box(I_max: float, magnet_free: bool) -> tuple[float, float, float, float]:
    """(i_d low, i_d high, i_q low, i_q high), A: where the drive's optima lie within the current
    limit. A PM machine's (an IPMSM's: magnet and reluctance torque both want i_d <= 0, and field
    weakening too) lie in the half disc i_d <= 0; a machine without magnet's in the whole disc
    (its mirror optima at +-i_d)."""
    return -I_max, (I_max if magnet_free else 0.0), -I_max, I_max


def covers(fmap: FluxMap, box, rect=None) -> bool:
    """Whether the grid (or the sub-grid rect = (a, b, c, d), inclusive indices) holds the box."""
    a, b, c, d = rect if rect is not None else (0, len(fmap.i_d) - 1, 0, len(fmap.i_q) - 1)
    tol = 1e-9 * max(abs(x) for x in box) if any(box) else 0.0
    return bool(fmap.i_d[a] <= box[0] + tol and fmap.i_d[b] >= box[1] - tol and
            fmap.i_q[c] <= box[2] + tol and fmap.i_q[d] >= box[3] - tol)


def legal_rectangle(fmap: FluxMap, boxes: np.ndarray, box) -> tuple[int, int, int, int] | None:
    """A large sub-grid (a, b, c, d: inclusive index ranges of i_d and i_q) free of the defect
    boxes and holding the current box `box`; None if no sub-grid does. Greedy: while a defect is
    inside, move the side that excludes the most defects per grid point lost (each side moved just
    past the nearest defect), never past the box."""
    rect = [0, len(fmap.i_d) - 1, 0, len(fmap.i_q) - 1]
    if not covers(fmap, box, rect):
        return None
    while True:
        a, b, c, d = rect
        inside = boxes[(boxes[:, 0] >= a) & (boxes[:, 1] <= b) & (boxes[:, 2] >= c) & (boxes[:, 3] <= d)]
        if len(inside) == 0:
            return tuple(rect)
        best = None
        for side, value in ((0, inside[:, 0].min() + 1), (1, inside[:, 1].max() - 1),
                            (2, inside[:, 2].min() + 1), (3, inside[:, 3].max() - 1)):
            cand = list(rect)
            cand[side] = int(value)
            if cand[0] > cand[1] or cand[2] > cand[3] or not covers(fmap, box, cand):
                continue
            a2, b2, c2, d2 = cand
            left = ((inside[:, 0] >= a2) & (inside[:, 1] <= b2) & (inside[:, 2] >= c2) & (inside[:, 3] <= d2)).sum()
            lost = (b - a + 1) * (d - c + 1) - (b2 - a2 + 1) * (d2 - c2 + 1)
            score = (len(inside) - left) / max(lost, 1)
            if best is None or score > best[0]:
                best = (score, cand)
        if best is None:
            return None
        rect = best[1]


def noise(fmap: FluxMap) -> dict:
    """Noise of the flux values (Wb), from the 4th differences along both axes (robust: the
    median absolute deviation), per flux; a smooth map gives ~ the rounding of its digits."""
    out = {}
    for name, psi in (("psi_d", fmap.psi_d), ("psi_q", fmap.psi_q)):
        diffs = [np.diff(psi, 4, axis=ax).ravel() for ax in (0, 1) if psi.shape[ax] > 4]
        if not diffs:
            out[name] = math.nan
            continue
        dd = np.concatenate(diffs)
        mad = np.median(np.abs(dd - np.median(dd)))
        out[name] = float(mad / MAD_NORMAL / math.sqrt(FOURTH_DIFF_VAR))
    return out


def monotone_projection(fmap: FluxMap, j0: int, k0: int, min_slope_rel: float = 1e-6):
    """psi_d made strictly increasing along i_d and psi_q along i_q, from the zero-current line
    (index j0 of i_d, k0 of i_q) outward: a point that does not rise above its inner neighbour is
    set to that neighbour plus min_slope_rel times the line's mean slope times the step. Returns
    (psi_d, psi_q, changed mask)."""
    psi_d, psi_q = fmap.psi_d.copy(), fmap.psi_q.copy()
    changed = np.zeros(psi_d.shape, bool)
    for psi, axis_values, centre, axis in ((psi_d, fmap.i_d, j0, 0), (psi_q, fmap.i_q, k0, 1)):
        p = np.moveaxis(psi, axis, 0)
        ch = np.moveaxis(changed, axis, 0)
        span = (p[-1] - p[0]) / (axis_values[-1] - axis_values[0])
        slope = min_slope_rel * np.maximum(np.abs(span), 1e-300)
        for j in range(centre + 1, len(axis_values)):
            floor = p[j - 1] + slope * (axis_values[j] - axis_values[j - 1])
            bad = p[j] < floor
            p[j] = np.where(bad, floor, p[j])
            ch[j] |= bad
        for j in range(centre - 1, -1, -1):
            ceil = p[j + 1] - slope * (axis_values[j + 1] - axis_values[j])
            bad = p[j] > ceil
            p[j] = np.where(bad, ceil, p[j])
            ch[j] |= bad
    return psi_d, psi_q, changed
