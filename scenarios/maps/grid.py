"""From a FEM tool's samples to the contract's grid: psi_d(i_d, i_q), psi_q(i_d, i_q) on ascending
i_d x i_q axes, peak A and Wb, PM flux on +d (docs/spec/INTERFACE.md). Each step says what
it changed in a note, so that an imported map states how it was made:

- dq frame: the PM flux (the flux at the sample nearest zero current) is turned onto +d by a
  rotation of the frame by a multiple of 90 degrees (SyR-e's "SR" convention has it on -q);
  a rotation keeps the torque T = 1.5 p (psi_d i_q - psi_q i_d) and the grid rectangular.
- layout: MATLAB meshgrid (i_d along axis 1) or ndgrid (i_d along axis 0), axes in either
  direction; anything else that is not a magnitude x angle grid is refused.
- phase-advance grids (current magnitude x advance angle): resampled onto a rectangular grid
  covering them by a bicubic spline in (|i|, angle); corners outside the sampled disc are
  extrapolated linearly in |i| from its rim.
- half and quarter maps: completed by the machine's symmetry in symmetry.py.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import RectBivariateSpline

from scenarios.maps.error import MapImportError
from scenarios.maps.formats import RawMap

#: grid values closer than this (relative to the largest current) are the same grid line
GRID_TOL = 1e-9
#: samples of one current magnitude (or angle) may differ by this, relative (rad): exports round
POLAR_TOL = 1e-6
#: the PM flux must lie within this of a dq axis to say which axis it is on (degrees)
PM_AXIS_TOL_DEG = 15.0
#: below this fraction of the largest flux, the map has no PM flux to tell the axes by
PM_FLUX_MIN_RATIO = 0.02
#: the cubic splines of the readers (scenarios/flux_map.py and the FMUs) need this many points per axis
MIN_POINTS = 4


def as_2d(raw: RawMap) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list]:
    """Currents and fluxes as four arrays of one 2-D shape (1-D current axes expanded)."""
    kd, kq, kfd, kfq = raw.keys
    psi_d, psi_q = raw.psi_d, raw.psi_q
    notes = []
    for k, a in ((kfd, psi_d), (kfq, psi_q)):
        if a.ndim != 2 or min(a.shape) < 2:
            raise MapImportError(None, k, "a 2-D array over the current grid", f"shape {a.shape}")
    if psi_d.shape != psi_q.shape:
        raise MapImportError(None, kfq, f"the shape of {kfd} {psi_d.shape}", f"shape {psi_q.shape}")
    shape = psi_d.shape
    i_d, i_q = (np.squeeze(a) if a.ndim == 2 and 1 in a.shape else a for a in (raw.i_d, raw.i_q))
    if i_d.ndim == 1 and i_q.ndim == 1:
        nd, nq = len(i_d), len(i_q)
        if shape == (nq, nd) and (nd != nq or raw.square_axis0 == "i_q"):
            i_d, i_q = np.meshgrid(i_d, i_q)           # i_d along axis 1
            if nd == nq:
                notes.append(f"square grid with 1-D axes: i_q taken along the rows, as {raw.source_format} writes")
        elif shape == (nd, nq):
            i_d, i_q = np.meshgrid(i_d, i_q, indexing="ij")
            if nd == nq:
                notes.append(f"square grid with 1-D axes: i_d taken along the rows, as {raw.source_format} writes")
        else:
            raise MapImportError(None, kfd, f"shape ({nd}, {nq}) or ({nq}, {nd}) to match {kd} and {kq}",
                                 f"shape {shape}")
    for k, a in ((kd, i_d), (kq, i_q)):
        if a.shape != shape:
            raise MapImportError(None, k, f"the shape of the flux arrays {shape}", f"shape {a.shape}")
    for k, a in zip(raw.keys, (i_d, i_q, psi_d, psi_q)):
        bad = ~np.isfinite(a)
        if bad.any():
            idx = tuple(int(x) for x in np.argwhere(bad)[0])
            raise MapImportError(None, k, "finite numbers", f"{int(bad.sum())} NaN or Inf, the first at index {idx}")
    return i_d, i_q, psi_d, psi_q, notes


def rotate_pm_onto_d(i_d, i_q, psi_d, psi_q, key: str):
    """Turn the dq frame by k * 90 deg so that the PM flux is on +d. Returns the four arrays, what
    was done (None: nothing to say) and whether the frame turned. A map without PM flux keeps its
    frame unless its d axis is the high-inductance one (SyR-e's synchronous-reluctance
    convention), then it turns by 90 deg."""
    i = i_d + 1j * i_q
    psi = psi_d + 1j * psi_q
    k0 = np.unravel_index(np.argmin(np.abs(i)), i.shape)
    psi_0 = psi[k0]
    scale = np.abs(psi).max()
    if abs(psi_0) >= PM_FLUX_MIN_RATIO * scale:
        angle = math.degrees(math.atan2(psi_0.imag, psi_0.real))
        quarter = round(angle / 90.0)
        if abs(angle - 90.0 * quarter) > PM_AXIS_TOL_DEG:
            raise MapImportError(None, key, f"the PM flux (at zero current) along a dq axis (within "
                                 f"{PM_AXIS_TOL_DEG:g} deg)", f"{abs(psi_0):.4g} Wb at {angle:.1f} deg from +d")
        turns = (-quarter) % 4
        why = f"PM flux found on {('+d', '+q', '-d', '-q')[quarter % 4]}"
    else:
        # No PM: the contract's frame has d on the low-inductance axis (as an IPMSM's PM axis).
        L_d = np.sum(psi_d * i_d) / max(np.sum(i_d**2), 1e-300)
        L_q = np.sum(psi_q * i_q) / max(np.sum(i_q**2), 1e-300)
        if not L_d > 1.05 * L_q:
            return i_d, i_q, psi_d, psi_q, (f"no PM flux (below {PM_FLUX_MIN_RATIO:.0%} of the largest): a "
                                            "synchronous-reluctance map, d on its low-inductance axis already"), False
        turns = 1
        why = f"no PM flux and L_d {L_d:.3g} H > L_q {L_q:.3g} H (synchronous-reluctance convention)"
    if turns == 0:
        return i_d, i_q, psi_d, psi_q, None, False
    r = 1j**turns  # exact for k * 90 deg: multiplies by 1, j, -1, -j
    i, psi = i * r, psi * r
    return i.real, i.imag, psi.real, psi.imag, f"{why}: dq frame turned by {90 * turns} deg to put it on +d", True


def _axis(values: np.ndarray, key: str, what: str) -> np.ndarray:
    """A strictly monotone grid axis, returned ascending."""
    d = np.diff(values)
    if not ((d > 0).all() or (d < 0).all()):
        k = int(np.argmax(~(d > 0) if d[0] > 0 else ~(d < 0)))
        raise MapImportError(None, key, f"a strictly monotone {what} axis",
                             f"{values[k]:.6g} followed by {values[k + 1]:.6g} at index {k}")
    return values if d[0] > 0 else values[::-1]


def rectangular(i_d, i_q, psi_d, psi_q, keys):
    """(i_d, i_q, psi_d, psi_q, note) on ascending axes with i_d along axis 0, if the samples form
    an i_d x i_q grid (meshgrid or ndgrid layout); None if they do not."""
    tol = GRID_TOL * max(np.abs(i_d).max(), np.abs(i_q).max(), 1e-300)
    for ax_d in (0, 1):
        if np.ptp(i_d, axis=1 - ax_d).max() <= tol and np.ptp(i_q, axis=ax_d).max() <= tol:
            break
    else:
        return None
    if ax_d == 1:  # meshgrid: transpose to i_d along axis 0
        i_d, i_q, psi_d, psi_q = i_d.T, i_q.T, psi_d.T, psi_q.T
    d_axis, q_axis = i_d[:, 0], i_q[0, :]
    if len(d_axis) < 2 or len(q_axis) < 2:
        return None
    d_sorted = _axis(d_axis, keys[0], "i_d")
    q_sorted = _axis(q_axis, keys[1], "i_q")
    if d_sorted[0] != d_axis[0]:
        psi_d, psi_q = psi_d[::-1, :], psi_q[::-1, :]
    if q_sorted[0] != q_axis[0]:
        psi_d, psi_q = psi_d[:, ::-1], psi_q[:, ::-1]
    note = "meshgrid layout (i_d along the columns) transposed" if ax_d == 1 else None
    return d_sorted.copy(), q_sorted.copy(), np.ascontiguousarray(psi_d), np.ascontiguousarray(psi_q), note


def polar(i_d, i_q, psi_d, psi_q, keys):
    """The samples as a magnitude x angle grid: (|i| axis, angle axis (rad, ascending,
    unwrapped), psi_d, psi_q with magnitude along axis 0); None if they are not one."""
    r = np.hypot(i_d, i_q)
    tol = POLAR_TOL * max(r.max(), 1e-300)
    for ax_m in (0, 1):
        if np.ptp(r, axis=1 - ax_m).max() <= tol:
            break
    else:
        return None
    if ax_m == 1:
        i_d, i_q, r, psi_d, psi_q = i_d.T, i_q.T, r.T, psi_d.T, psi_q.T
    mags = r[:, 0]
    if len(mags) < 2 or r.shape[1] < 2:
        return None
    rim = int(np.argmax(mags))
    theta = np.arctan2(i_q, i_d)
    live = mags > tol
    # the angle is the same along the magnitude axis (rows of zero current excepted)
    spread = np.abs(np.angle(np.exp(1j * (theta[live] - theta[rim][None, :])))).max()
    if spread > POLAR_TOL:
        return None
    key = keys[0] + ", " + keys[1]
    mags = _axis(mags, key, "current magnitude")
    if mags[0] != r[0, 0]:
        psi_d, psi_q = psi_d[::-1], psi_q[::-1]
    angles = np.unwrap(theta[rim])
    angles_sorted = _axis(angles, key, "current angle")
    if angles_sorted[0] != angles[0]:
        psi_d, psi_q = psi_d[:, ::-1], psi_q[:, ::-1]
    return mags.copy(), angles_sorted.copy(), np.ascontiguousarray(psi_d), np.ascontiguousarray(psi_q)


def resample_polar(mags, angles, psi_d, psi_q):
    """Bicubic splines in (|i|, angle) evaluated on the rectangular grid that covers the sampled
    region with the radial step of the data. Returns (i_d, i_q, psi_d, psi_q, note)."""
    if len(mags) < MIN_POINTS or len(angles) < MIN_POINTS:
        raise MapImportError(None, "grid", f">= {MIN_POINTS} current magnitudes and angles",
                             f"{len(mags)} x {len(angles)}")
    if mags[0] != 0.0:  # zero current: the PM flux, and no extrapolation towards the centre
        raise MapImportError(None, "grid", "current magnitudes from 0 A", f"from {mags[0]:.6g} A")
    span = angles[-1] - angles[0]
    step = np.diff(angles).min()
    full = span + step >= 2 * math.pi - 1e-6
    if full:
        # Periodic: drop a repeated 360 deg column, pad three columns on each side.
        if abs(span - 2 * math.pi) < 1e-6:
            angles, psi_d, psi_q = angles[:-1], psi_d[:, :-1], psi_q[:, :-1]
        pad = 3
        angles = np.concatenate([angles[-pad:] - 2 * math.pi, angles, angles[:pad] + 2 * math.pi])
        psi_d = np.concatenate([psi_d[:, -pad:], psi_d, psi_d[:, :pad]], axis=1)
        psi_q = np.concatenate([psi_q[:, -pad:], psi_q, psi_q[:, :pad]], axis=1)
    sd = RectBivariateSpline(mags, angles, psi_d, kx=3, ky=3, s=0)
    sq = RectBivariateSpline(mags, angles, psi_q, kx=3, ky=3, s=0)
    R = mags[-1]
    # the rectangle: the bounding box of the sampled points, on the data's radial step, through 0
    theta_dense = np.linspace(angles[0], angles[-1], 721) if not full else np.linspace(0, 2 * math.pi, 721)
    h = R / (len(mags) - 1)
    bounds = []
    for c in (np.cos(theta_dense), np.sin(theta_dense)):
        lo, hi = min((R * c).min(), 0.0), max((R * c).max(), 0.0)  # the sector and its apex, zero current
        bounds.append(h * np.arange(math.floor(lo / h + 1e-9), math.ceil(hi / h - 1e-9) + 1))  # rounding-proof
    i_d, i_q = bounds
    I_d, I_q = np.meshgrid(i_d, i_q, indexing="ij")
    r = np.hypot(I_d, I_q)
    t = np.arctan2(I_q, I_d)
    t = angles[0] + np.mod(t - angles[0], 2 * math.pi)   # into [angles[0], angles[0] + 2 pi)
    if not full:  # a sector: points just outside it (the box's edges) take the nearest edge ray
        over = t > angles[-1]
        nearer_start = (angles[0] + 2 * math.pi - t) < (t - angles[-1])
        t = np.where(over & nearer_start, angles[0], np.where(over, angles[-1], t))
    rr = np.minimum(r, R)
    out = []
    for s in (sd, sq):
        v = s.ev(rr, t)
        outside = r > R
        v[outside] += (r[outside] - R) * s.ev(np.full(outside.sum(), R), t[outside], dx=1)
        out.append(v)
    n_out = int((r > R * (1 + 1e-12)).sum())
    note = (f"magnitude x angle grid ({len(mags)} x {len(angles) - (6 if full else 0)} points, |i| <= {R:.6g} A, "
            f"angles {math.degrees(angles[0] + (3 * step if full else 0)):.1f} ... "
            f"{math.degrees(angles[-1] - (3 * step if full else 0)):.1f} deg) resampled onto {len(i_d)} x {len(i_q)} "
            f"i_d x i_q points, step {h:.6g} A, by bicubic splines in (|i|, angle); {n_out} points outside "
            f"|i| = {R:.6g} A extrapolated linearly in |i|")
    return i_d, i_q, out[0], out[1], note


def magnet_free(i_d, i_q, psi_d, psi_q) -> bool:
    """No PM flux: the flux at the sample nearest zero current below PM_FLUX_MIN_RATIO of the largest."""
    if np.ndim(i_d) == 1:
        i_d, i_q = np.meshgrid(i_d, i_q, indexing="ij")
    k0 = np.unravel_index(np.argmin(np.hypot(i_d, i_q)), np.shape(psi_d))
    return bool(math.hypot(psi_d[k0], psi_q[k0]) < PM_FLUX_MIN_RATIO * np.hypot(psi_d, psi_q).max())
