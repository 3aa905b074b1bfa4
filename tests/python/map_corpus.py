"""The corpus of flux maps the controller is checked on, in one place for every test that wants it:
the default motor, the city-EV motor, the measured Baldor PM-SyRM, the Prius-class map of the PLECS
demo, SyR-e's RAWP synchronous-reluctance machine (no magnet) and a strongly saturating map from
tools/saturating_map.py. Each entry names its drive's data (pole pairs, R_s, I_max, u_dc, top
speed) from its source (scenarios/data/fluxmaps/real/SOURCES.md, the map's metadata).

Every map as published: the Prius map with its fold at i_d = 130 A (outside the operating region:
the FMUs accept it with a warning), RAWP as `map import` makes it from SyR-e's .mat (the half map
completed by the symmetry of a machine without magnet; psi_q not monotone at |i_q| >= 47.3 A,
beyond its 30 A). `CorpusMap.path(tmp)` writes what is needed into tmp and returns the CSV to load.
"""
from __future__ import annotations

import math
import shutil
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from scenarios.core.paths import DATA_DIR, ROOT
from scenarios.maps.flux_map import DEFAULT_MAP

RPM = math.pi / 30.0  # rad/s per r/min
FLUXMAPS = DATA_DIR / "fluxmaps"


@dataclass(frozen=True)
class CorpusMap:
    name: str
    pole_pairs: int
    R_s: float         # Ohm
    I_max: float       # A peak
    u_dc: float        # V
    w_m_max: float     # rad/s
    make: Callable[[Path], Path] = field(compare=False, repr=False)  # tmp dir -> contract CSV
    magnet_free: bool = False  # optima tie in mirror pairs: the controller keeps to i_d <= 0

    def path(self, tmp: Path) -> Path:
        return self.make(Path(tmp))


def _as_is(path: Path) -> Callable[[Path], Path]:
    return lambda tmp: path


#: RAWP's contract CSV as imported first this session: the modules that take the corpus get a copy
#: (the import is deterministic; its iron-loss fit alone takes seconds)
_RAWP_IMPORTED: list[Path] = []


def _rawp(tmp: Path) -> Path:
    out = tmp / "syre_rawp.csv"
    if not out.exists():
        if _RAWP_IMPORTED and _RAWP_IMPORTED[0].is_file():
            shutil.copyfile(_RAWP_IMPORTED[0], out)
        else:
            from scenarios.maps.importer import import_map, write_contract_csv
            write_contract_csv(import_map(FLUXMAPS / "real" / "syre_RAWP.mat"), out)
            _RAWP_IMPORTED[:] = [out]
    return out


def _saturating(tmp: Path) -> Path:
    from tools.saturating_map import SaturatingMachine, write_map
    out = tmp / "saturating_Is0.2_x0.15.csv"
    if not out.exists():
        write_map(out, SaturatingMachine(0.2, None, 0.15))
    return out


CORPUS = [
    CorpusMap("default", 4, 0.012, 500.0, 355.0, 12000 * RPM, _as_is(DEFAULT_MAP)),
    CorpusMap("city_ev", 6, 0.015, 470.0, 355.0, 11400 * RPM,
              _as_is(ROOT / "scenarios" / "drives" / "city_ev_motor.csv")),
    # the Baldor's drive as the existing tests run it (test_controller_optimal.py)
    CorpusMap("baldor_measured", 2, 0.63, 18.0, 540.0, 500.0, _as_is(FLUXMAPS / "baldor_5p6kW_pmsyrm_measured.csv")),
    # PLECS demo: 4 pole pairs, R_s 0.015 Ohm; I_max 200 A (the grid's reach), 500 V (ORNL, OSTI 890029), 6000 r/min
    CorpusMap("prius", 4, 0.015, 200.0, 500.0, 6000 * RPM, _as_is(FLUXMAPS / "real" / "plecs_prius_as_published.csv")),
    # SyR-e's motorModel.data: p 3, Rs 0.44 Ohm, Imax 30 A, Vdc 565 V, nmax 3000 r/min
    CorpusMap("syre_rawp", 3, 0.44, 30.0, 565.0, 3000 * RPM, _rawp, magnet_free=True),
    CorpusMap("saturating", 4, 0.012, 500.0, 355.0, 12000 * RPM, _saturating),
]
#: the tie convention's machine: RAWP, whose import is the whole map (both i_d halves, mirror twins)
RAWP_MIRRORED = CorpusMap("syre_rawp_mirrored", 3, 0.44, 30.0, 565.0, 3000 * RPM, _rawp, magnet_free=True)
BY_NAME = {m.name: m for m in [*CORPUS, RAWP_MIRRORED]}


#: the corpus tests' speed bands (of w_m_max): MTPA; field weakening; deep field weakening, MTPV
SPEED_BANDS = ((0.0, 0.3), (0.3, 0.65), (0.65, 1.0))
#: their torque bands (of the peak torque): within reach, and beyond it (the command clamped)
TORQUE_BANDS = ((0.02, 0.95), (1.05, 1.4))
#: the corpus tests' u_dc (of the map's) and magnet temperature (K) ranges
U_DC_RANGE = (0.85, 1.1)
T_MAGNET_RANGE = (253.15, 393.15)


def operating_points(rng, m: CorpusMap, T_peak: float, n_per_cell: int, w_min: float = 0.0):
    """Four quadrants x the speed bands (the lowest from w_min of w_m_max) x the torque bands,
    n_per_cell random points in each cell; u_dc and the magnet temperature random. Dicts of the
    controller's inputs T_ref, w_m, u_dc, T_magnet."""
    for T_sign in (1, -1):
        for w_sign in (1, -1):
            for lo, hi in SPEED_BANDS:
                for t_lo, t_hi in TORQUE_BANDS:
                    for _ in range(n_per_cell):
                        yield dict(T_ref=float(T_sign * rng.uniform(t_lo, t_hi) * T_peak),
                                   w_m=float(w_sign * rng.uniform(max(lo, w_min), hi) * m.w_m_max),
                                   u_dc=float(rng.uniform(*U_DC_RANGE) * m.u_dc),
                                   T_magnet=float(rng.uniform(*T_MAGNET_RANGE)))


def bench_arguments(tmp: Path) -> list[str]:
    """bench_controller's --map arguments for the whole corpus, its maps written into tmp."""
    args = []
    for m in CORPUS:
        args += ["--map", m.name, str(m.path(tmp)), str(m.pole_pairs), repr(m.R_s), repr(m.I_max), repr(m.u_dc),
                 repr(m.w_m_max)]
    return args


def main(argv=None) -> int:
    """python tests/python/map_corpus.py --bench [DIR]: write the corpus into DIR (a temporary
    folder by default) and run build/bin/bench_controller on it (recursion 2 with its check)."""
    import argparse
    import subprocess
    import sys
    import tempfile
    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("--bench", action="store_true")
    ap.add_argument("dir", nargs="?")
    ns = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(ns.dir or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        args = bench_arguments(folder)
        if not ns.bench:
            print(" ".join(args))
            return 0
        return subprocess.call([str(ROOT / "build" / "bin" / "bench_controller"), "--corpus-only", *args],
                               stdout=sys.stdout)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))  # run as a script: the repository's tools/ (the saturating map's generator)
    raise SystemExit(main())
