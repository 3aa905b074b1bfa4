"""Completing partial flux maps by the machine's symmetry (half and quarter maps from FEM runs on
one quadrant). The magnetic circuit of every machine is symmetric about the d axis:

    psi_d(i_d, -i_q) = psi_d(i_d, i_q),  psi_q(i_d, -i_q) = -psi_q(i_d, i_q)   (even / odd in i_q)

and a machine without magnet is also symmetric about the q axis (nothing tells +d from -d):

    psi_d(-i_d, i_q) = -psi_d(i_d, i_q),  psi_q(-i_d, i_q) = psi_q(i_d, i_q)   (odd / even in i_d)

(Hinkkanen et al., IEEE TIA 2017, doi 10.1109/TIA.2016.2644624, sec. II: the saturation
models' magnetic energy is even in each flux of a machine without PM.) A PM machine has no
symmetry in d: its i_d > 0 half cannot be made from the i_d < 0 one.
"""
from __future__ import annotations

import numpy as np

#: grid values within this (relative to the largest current) of zero are the zero line
ZERO_TOL = 1e-9


def mirror(axis_values: np.ndarray, even: np.ndarray, odd: np.ndarray, axis: int):
    """Complete a one-signed axis (values all >= 0 or all <= 0) by mirror images: `even` keeps its
    values, `odd` changes sign. axis: the array axis the values run along. Returns (axis, even,
    odd, made), made a boolean array of the points that are mirror images, or None if the axis
    already has both signs."""
    tol = ZERO_TOL * max(np.abs(axis_values).max(), 1e-300)
    if axis_values[0] < -tol and axis_values[-1] > tol:
        return None
    negative = axis_values[-1] <= tol
    x, e, o = axis_values, np.moveaxis(even, axis, 0), np.moveaxis(odd, axis, 0)
    if negative:  # mirror the other way round: flip, complete, flip back
        x, e, o = -x[::-1], e[::-1], -o[::-1]
    k = 1 if abs(x[0]) <= tol else 0  # the zero line is its own mirror image
    n_new = len(x) - k
    x = np.concatenate([-x[k:][::-1], x])
    e = np.concatenate([e[k:][::-1], e])
    o = np.concatenate([-o[k:][::-1], o])
    made = np.zeros(len(x), bool)
    made[:n_new] = True
    if k == 1:
        x[n_new] = 0.0
    if negative:
        x, e, o, made = -x[::-1], e[::-1], -o[::-1], made[::-1]
    return x, np.moveaxis(e, 0, axis), np.moveaxis(o, 0, axis), made


def complete(i_d, i_q, psi_d, psi_q, magnet_free: bool):
    """Complete a half or quarter map (i_d x i_q, psi arrays indexed [i_d, i_q]). Returns (i_d, i_q,
    psi_d, psi_q, notes, made): notes say what was done, made marks the points that were made
    (True) rather than given. A PM map with one sign of i_d only is left so (no symmetry)."""
    notes = []
    made = np.zeros(psi_d.shape, bool)
    sign = "<=" if i_q[-1] <= ZERO_TOL * max(np.abs(i_q).max(), 1e-300) else ">="
    r = mirror(i_q, psi_d, psi_q, axis=1)
    if r is not None:
        i_q, psi_d, psi_q, new = r
        made = _expand(made, new)
        notes.append(_step_note(f"half map (i_q {sign} 0 only) mirrored about the d axis: psi_d even, psi_q odd "
                                f"in i_q ({int(new.sum())} i_q lines made)", psi_q, i_q))
    if magnet_free:
        r = mirror(i_d, psi_q.T, psi_d.T, axis=1)
        if r is not None:
            i_d, psi_q_t, psi_d_t, new = r
            psi_d, psi_q = psi_d_t.T, psi_q_t.T
            made = _expand(made.T, new).T
            notes.append(_step_note("no magnet: the map mirrored about the q axis as well, psi_d odd, psi_q even "
                                    f"in i_d ({int(new.sum())} i_d lines made)", psi_d.T, i_d))
    return i_d, i_q, np.ascontiguousarray(psi_d), np.ascontiguousarray(psi_q), notes, made


def _expand(made: np.ndarray, new: np.ndarray) -> np.ndarray:
    """The made-mask after mirroring along its axis 1: the old columns where new is False, True else."""
    out = np.ones((made.shape[0], len(new)), bool)
    out[:, ~new] = made
    return out


def _step_note(note: str, odd: np.ndarray, axis_values: np.ndarray) -> str:
    """An odd function must vanish on the zero line; if the data do not, the mirror has a step."""
    zero = np.abs(axis_values) <= ZERO_TOL * max(np.abs(axis_values).max(), 1e-300)
    if zero.any():
        off = np.abs(odd[:, zero]).max()
        if off > 1e-3 * np.abs(odd).max():
            note += f" (the odd flux on the zero line is up to {off:.3g} Wb, not 0: the mirrored map has a step there)"
    return note
