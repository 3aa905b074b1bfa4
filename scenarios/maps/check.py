"""python -m scenarios map check FILE: is a flux map usable as it is, and what would make it so.

Reports (check.md, check.json in --out):
- the grid, whether the machine has a magnet, the current limit I_max (metadata, --drive,
  --I-max, else the grid's reach; named) and whether the grid covers the currents the drive
  uses there (scenarios.maps.legal.required_box);
- the legal domain: the grid lines where psi_d does not rise with i_d or psi_q with i_q, the
  points where the incremental inductances fold (each kind counted, the one nearest zero
  current named, and how many lie within I_max), and the largest legal sub-grid holding the
  drive's currents (what `map repair` would crop to);
- reciprocity dpsi_d/di_q - dpsi_q/di_d within I_max (scenarios.maps.show.reciprocity);
- the noise of the flux values (scenarios.maps.legal.noise);
- the FMUs' own verdict: each FMU initialised on the map, its log (the one source of truth of
  acceptance; scenarios.maps.fmu_verdict).

Exit status: 0 every FMU accepts the map, 1 one refuses it, 2 bad input.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from scenarios.core.boundary import check_writable, printable, strict_json, write_atomically
from scenarios.maps import legal
from scenarios.maps.flux_map import FluxMap, read_flux_map
from scenarios.maps.fmu_verdict import verdicts
from scenarios.maps.importer import contract_csv


@dataclass
class DefectSummary:
    kind: str
    count: int
    within_I_max: int          # in the I_max circle
    within_drive_currents: int  # in the I_max circle and the drive's half (i_d <= 0 with a magnet)
    within_refused_box: int    # in the FMUs' required box (the drive's currents and a margin): refused
    nearest_A: list | None     # (i_d, i_q) of the one nearest zero current
    nearest_abs_A: float | None


@dataclass
class MapCheck:
    map_file: str
    contract_csv: str
    grid: str
    magnet_free: bool
    I_max_A: float
    assumed: list
    required_box_A: list          # i_d low, high, i_q low, high
    grid_covers_I_max: bool
    defects: list
    legal_rectangle_A: list | None  # i_d low, high, i_q low, high of the largest legal sub-grid, or None
    legal_rectangle_covers_I_max: bool
    reciprocity_max_H: float
    reciprocity_rel: float
    reciprocity_at_A: list
    noise_Wb: dict
    noise_rel: dict               # noise / largest |psi|
    fmus: list = field(default_factory=list)   # {fmu, accepted, log}

    @property
    def accepted(self) -> bool:
        return all(f["accepted"] for f in self.fmus)

    @property
    def verdict(self) -> str:
        """The FMUs' verdict in a few words: accept, accept with a warning, REFUSE."""
        if not self.accepted:
            return "REFUSE it"
        return "accept it with a warning" if any(f["verdict"] != "accepted" for f in self.fmus) else "accept it"


def analyse(fmap: FluxMap, I_max: float):
    """(magnet_free, required box, defects, defect summaries, legal rectangle or None)."""
    no_magnet = not legal.has_magnet(fmap)
    box = legal.required_box(I_max, no_magnet)
    refused = legal.refused_box(fmap, I_max)
    found = legal.defects(fmap)
    summaries = []
    for kind, boxes in (("psi_d not increasing in i_d", found.psi_d_falls),
                        ("psi_q not increasing in i_q", found.psi_q_falls),
                        ("incremental inductances fold (det <= 0)", found.folds)):
        near = legal.nearest(fmap, boxes)
        pts = np.array([legal.where(fmap, b) for b in boxes]) if len(boxes) else np.zeros((0, 2))
        in_circle = np.hypot(pts[:, 0], pts[:, 1]) <= I_max
        inside = int(in_circle.sum())
        driven = int((in_circle & (pts[:, 0] >= box[0]) & (pts[:, 0] <= box[1])).sum())
        in_refused = int(((pts[:, 0] >= refused[0]) & (pts[:, 0] <= refused[1]) & (pts[:, 1] >= refused[2])
                          & (pts[:, 1] <= refused[3])).sum())
        summaries.append(DefectSummary(kind, len(boxes), inside, driven, in_refused, list(near[0]) if near else None,
                                       near[1] if near else None))
    rect = legal.legal_rectangle(fmap, found.all(), box)
    return no_magnet, box, found, summaries, rect


def readable(path: Path) -> tuple[Path, object]:
    """(the contract CSV, its FluxMap) of a map file, or MapImportError naming the file (exit 2):
    the readers' own words (a header, a metadata value, a grid too small for the spline)."""
    from scenarios.maps.error import MapImportError
    try:
        csv = contract_csv(path)
        return csv, read_flux_map(csv)
    except MapImportError:
        raise
    except Exception as e:  # noqa: BLE001 - every reader's refusal, scipy's too: bad input, not a crash
        raise MapImportError(path, "(file)", "a readable flux map", f"{printable(str(e))}") from None


def machine_of(path: Path, fmap, I_max, drive):
    """show.machine_parameters, a bad metadata value refused naming the file (exit 2)."""
    from scenarios.maps.error import MapImportError
    from scenarios.maps.show import machine_parameters
    try:
        return machine_parameters(fmap, None, I_max, drive)
    except (KeyError, ValueError, OverflowError) as e:
        if isinstance(e, MapImportError):
            raise
        raise MapImportError(path, "(metadata)", "numbers the schema allows in the map's `# key: value` metadata",
                             printable(str(e))) from None


def check_map(path: Path, out: Path, build: Path, I_max: float | None = None, drive=None) -> MapCheck:
    from scenarios.maps.show import reciprocity
    path = Path(path)
    csv, fmap = readable(path)
    params, assumed, _ = machine_of(path, fmap, I_max, drive)
    check_writable(out, "--out")  # after the map's refusals (no folder left for them), before the work
    I_lim = float(params["I_max"])
    no_magnet, box, _, summaries, rect = analyse(fmap, I_lim)
    _, rec_max, rec_rel, rec_at = reciprocity(fmap, I_lim)
    noise = legal.noise(fmap)
    scale = float(np.hypot(fmap.psi_d, fmap.psi_q).max())
    c = MapCheck(
        map_file=str(path), contract_csv=str(csv),
        grid=f"{len(fmap.i_d)} x {len(fmap.i_q)} (i_d {fmap.i_d[0]:g} ... {fmap.i_d[-1]:g} A, "
             f"i_q {fmap.i_q[0]:g} ... {fmap.i_q[-1]:g} A)",
        magnet_free=no_magnet, I_max_A=I_lim, assumed=assumed, required_box_A=list(box),
        grid_covers_I_max=legal.covers(fmap, box), defects=[asdict(s) for s in summaries],
        legal_rectangle_A=None if rect is None else [float(fmap.i_d[rect[0]]), float(fmap.i_d[rect[1]]),
                                                    float(fmap.i_q[rect[2]]), float(fmap.i_q[rect[3]])],
        legal_rectangle_covers_I_max=rect is not None, reciprocity_max_H=rec_max, reciprocity_rel=rec_rel,
        reciprocity_at_A=rec_at, noise_Wb=noise, noise_rel={k: v / scale for k, v in noise.items()})
    c.fmus = [asdict(v) for v in verdicts(csv, params, build)]
    write_atomically(out / "check.json", strict_json(asdict(c) | {"accepted": c.accepted, "verdict": c.verdict},
                                                     indent=1))
    write_atomically(out / "check.md", markdown(c))
    return c


def markdown(c: MapCheck) -> str:
    box = ", ".join(f"{x:g}" for x in c.required_box_A)
    rect = (f"i_d {c.legal_rectangle_A[0]:g} ... {c.legal_rectangle_A[1]:g} A, i_q {c.legal_rectangle_A[2]:g} ... "
            f"{c.legal_rectangle_A[3]:g} A" if c.legal_rectangle_A else "none holds the drive's currents")
    lines = [f"# map check: `{Path(c.map_file).name}` — FMUs {c.verdict}", "",
             "Made by `python -m scenarios map check`; the numbers also in `check.json`.", "",
             "| quantity | value |", "|---|---|",
             f"| map (contract CSV read) | `{c.contract_csv}` |",
             f"| grid | {c.grid} |",
             f"| magnet | {'none (magnet-free: optima in mirror pairs +-i_d)' if c.magnet_free else 'yes'} |",
             f"| current limit I_max | {c.I_max_A:g} A |",
             f"| the drive's currents (i_d low, high, i_q low, high) | {box} A |",
             f"| grid covers them | {'yes' if c.grid_covers_I_max else 'NO'} |",
             f"| largest legal sub-grid holding them | {rect} |",
             f"| reciprocity max abs(dpsi_d/di_q - dpsi_q/di_d) within I_max | {c.reciprocity_max_H * 1e6:.4g} uH "
             f"({100 * c.reciprocity_rel:.3g} % of the largest incremental inductance) at i_d = "
             f"{c.reciprocity_at_A[0]:g} A, i_q = {c.reciprocity_at_A[1]:g} A |",
             f"| noise of psi_d, psi_q (4th differences, robust) | {c.noise_Wb['psi_d']:.3g} Wb, "
             f"{c.noise_Wb['psi_q']:.3g} Wb ({100 * c.noise_rel['psi_d']:.2g} %, {100 * c.noise_rel['psi_q']:.2g} % "
             "of the largest flux) |", "",
             "## Legal domain", "", "| defect | count | within the I_max circle | among the drive's currents | "
             "where the FMUs refuse (the drive's currents and a margin) | nearest zero current |",
             "|---|---:|---:|---:|---:|---|"]
    for d in c.defects:
        near = (f"i_d = {d['nearest_A'][0]:g} A, i_q = {d['nearest_A'][1]:g} A (abs(i) = {d['nearest_abs_A']:.4g} A)"
                if d["nearest_A"] else "—")
        lines.append(f"| {d['kind']} | {d['count']} | {d['within_I_max']} | {d['within_drive_currents']} | "
                     f"{d['within_refused_box']} | {near} |")
    lines += ["", "(the grid's own values and the map's bicubic spline: an analysis; the FMUs decide below)", "",
              "## The FMUs' verdict", ""]
    for f in c.fmus:
        lines.append(f"- **{f['fmu']}**: {f['verdict']}")
        lines += [f"  - `{m}`" for m in f["log"]]
    lines += ["", "## Assumed", ""] + ([f"- {a}" for a in c.assumed] or ["- nothing: every value from the map"])
    if not c.accepted:
        lines += ["", "What to do: `python -m scenarios map repair FILE --out FIXED.csv` writes a map the FMUs accept "
                  "(cropped to the legal sub-grid above, or a monotone projection), stating every change."]
    return "\n".join(lines) + "\n"
