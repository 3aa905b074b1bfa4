"""Real flux maps as published (issue 23): IpmsmController, IpmsmPlant and IpmsmDrive initialise on
each corpus map, with one warning where the map is not legal outside the drive's operating region
(fmu_src/machine/operating_region.hpp, docs/maps.md), and refuse a map that is not legal inside
it, naming where. The Prius map of the PLECS demo as published failed with "psi_d not strictly
increasing in i_d along i_q = -20 A ... at i_d = 130 A", SyR-e's RAWP map with psi_q not monotone
at |i_q| >= 47.3 A."""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenarios.core.paths import DATA_DIR
from scenarios.cosim.drive_fmu import DriveFmu
from scenarios.maps.flux_map import DEFAULT_MAP, FluxMap, read_flux_map, write_flux_map

from conftest import fmu_path

REAL = DATA_DIR / "fluxmaps" / "real"
WARNING = 1  # fmi2Warning


def mirrored_half_map(fmap: FluxMap) -> FluxMap:
    """A magnet-free machine's half map (i_d <= 0) completed: psi_d odd and psi_q even in i_d (a
    map that is complete already, as the importer may write it, is returned as it is)."""
    if fmap.i_d.max() > 0.0:
        return fmap
    assert fmap.psi_m == pytest.approx(0.0, abs=1e-12)
    neg = fmap.i_d < 0
    i_d = np.concatenate([fmap.i_d, -fmap.i_d[neg][::-1]])
    psi_d = np.concatenate([fmap.psi_d, -fmap.psi_d[neg][::-1]], axis=0)
    psi_q = np.concatenate([fmap.psi_q, fmap.psi_q[neg][::-1]], axis=0)
    return FluxMap(i_d, fmap.i_q, psi_d, psi_q, dict(fmap.metadata))


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """name -> (map path, parameters of the drive, u_dc, whether the map has defects outside)."""
    d = tmp_path_factory.mktemp("corpus")
    rawp_half = d / "rawp_half.csv"
    subprocess.run([sys.executable, "-m", "scenarios", "map", "import", str(REAL / "syre_RAWP.mat"), "--out",
                    str(rawp_half)], check=True, capture_output=True)
    rawp = d / "rawp.csv"
    write_flux_map(rawp, mirrored_half_map(read_flux_map(rawp_half)))
    return {
        # PLECS demo: 4 pole pairs, R_s 0.015 Ohm (SOURCES.md); I_max 200 A, u_dc 500 V (issue 23)
        "prius": (REAL / "plecs_prius_as_published.csv", dict(pole_pairs=4, R_s=0.015, I_max=200.0), 500.0, True),
        # SyR-e's motorModel.data: p 3, Rs 0.44 Ohm, Imax 30 A, Vdc 565 V
        "rawp": (rawp, dict(pole_pairs=3, R_s=0.4398, I_max=30.0), 565.0, True),
        # the measured Baldor map's metadata: 2 pole pairs, 0.63 Ohm; 8.8 A rms rated: 20 A peak within its grid
        "baldor": (DATA_DIR / "fluxmaps" / "baldor_5p6kW_pmsyrm_measured.csv",
                   dict(pole_pairs=2, R_s=0.63, I_max=20.0), 540.0, False),
        "default": (Path(DEFAULT_MAP), {}, 355.0, False),
    }


def _init(fmu_instances, name, path, params, **extra):
    inst = fmu_instances(name, logging_on=True)
    assert inst.setup() == 0 and inst.enter() == 0
    inst.set(flux_map=str(path), **{k: v for k, v in {**params, **extra}.items() if k in inst.fmu.vars})
    return inst, inst.exit()


def _map_warnings(inst) -> list[str]:
    return [m for s, _, m in inst.log.records if s == WARNING and "not legal at" in m]


@pytest.mark.parametrize("fmu", ["IpmsmController", "IpmsmPlant"])
@pytest.mark.parametrize("name", ["prius", "rawp", "baldor", "default"])
def test_each_fmu_initialises_on_each_corpus_map_warning_once(corpus, fmu_instances, fmu, name):
    path, params, _, defects = corpus[name]
    inst, status = _init(fmu_instances, fmu, path, params)
    assert status in (0, WARNING), inst.log.text()
    warnings = _map_warnings(inst)
    assert len(warnings) == (1 if defects else 0), inst.log.text()
    for w in warnings:
        assert "outside the drive's operating region" in w and "The map is used on" in w
        assert len(w.encode()) < 2000
        w.encode("utf-8")
    if name == "prius":  # where the published map fails: named
        assert "psi_d not strictly increasing in i_d along i_q = " in warnings[0]
    if name == "rawp":
        assert "psi_q not strictly increasing in i_q" in warnings[0]


def test_prius_refused_where_its_fold_is_inside_the_operating_region(corpus, fmu_instances):
    """Without a magnet the whole I_max disc is operated: the Prius map's fold at i_d = 130 A is then
    inside it (the same data with psi_d shifted so that psi_d(0, 0) = 0)."""
    path, params, _, _ = corpus["prius"]
    f = read_flux_map(path)
    shifted = FluxMap(f.i_d, f.i_q, f.psi_d - f.psi_m, f.psi_q, dict(f.metadata))
    out = corpus["rawp"][0].parent / "prius_no_magnet.csv"
    write_flux_map(out, shifted)
    for fmu in ("IpmsmController", "IpmsmPlant"):
        inst, status = _init(fmu_instances, fmu, out, params)
        assert status == 3, inst.log.text()  # fmi2Error
        text = inst.log.text()
        assert "psi_d not strictly increasing in i_d along i_q = " in text and "i_d = 130 A" in text, text
        assert "inside the drive's operating region" in text and "map repair" in text, text


def _drive(path, params, u_dc):
    return DriveFmu(fmu_path("IpmsmDrive"), params={"flux_map": str(path), **params}, u_dc=u_dc,
                    logging_on=True)


@pytest.mark.parametrize("name", ["prius", "rawp", "baldor", "default"])
def test_drive_initialises_on_each_corpus_map(corpus, name):
    path, params, u_dc, defects = corpus[name]
    with _drive(path, params, u_dc) as d:
        warnings = [m for _, _, m in d.messages if "not legal at" in m]
        # the controller and the plant both warn, the same text: it reaches the importer once
        assert len(warnings) == (1 if defects else 0), warnings
        s = d.advance(1e-2, 0.0, 10.0, u_dc, 293.15, 293.15)
        assert math.isfinite(s.T_e)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["prius", "rawp", "baldor", "default"])
def test_drive_delivers_the_torque_command_at_10ms(corpus, name):
    """At three speeds (below, near and above the speed where the largest flux on the map meets
    the voltage limit), T_ref = 10, 40, 70 and 100 % of T_max there, each held for 0.1 s at 10 ms
    steps: the last step's mean electromagnetic torque is T_cmd within 1 % of T_max, and T_cmd is
    T_ref (the command is not clamped away)."""
    path, params, u_dc, _ = corpus[name]
    fm = read_flux_map(path)
    p = params.get("pole_pairs", 4)
    w_voltage = u_dc / math.sqrt(3) / float(np.hypot(fm.psi_d, fm.psi_q).max()) / p  # rad/s, mechanical
    worst = 0.0
    for ratio in (0.3, 1.0, 2.0):
        w = ratio * w_voltage
        with _drive(path, params, u_dc) as d:
            s = d.advance(1e-2, 1e5, w, u_dc, 293.15, 293.15)  # beyond reach: T_cmd = T_max
            T_max = s.T_max
            assert T_max > 0
            for frac in (0.1, 0.4, 0.7, 1.0):
                for _ in range(10):
                    s = d.advance(1e-2, frac * T_max, w, u_dc, 293.15, 293.15)
                assert s.T_cmd == pytest.approx(min(frac * T_max, s.T_max), rel=1e-6, abs=1e-9 * T_max)
                err = abs(s.T_e - s.T_cmd) / s.T_max
                worst = max(worst, err)
                assert err < 0.01, (name, w, frac, s.T_e, s.T_cmd, s.T_max)
        print(f"{name}: w_m {w:.1f} rad/s, T_max {T_max:.2f} N m")
    print(f"{name}: worst |T_e - T_cmd| / T_max = {worst:.2e}")


def far_corner_fold() -> FluxMap:
    """A 500 A machine whose incremental inductances fold only at its far corner (i_d = 30 A,
    i_q = -600 A; issue 23): a saturating q axis (tanh, I_s = 300 A) and a cross-coupling bump of
    width 40 A there (the same map as tests/cpp/test_flux_map_acceptance.cpp's)."""
    L_d, L_q, I_s, s, a, b, c_d, c_q = 2e-4, 6e-4, 300.0, 40.0, 5e-5, 3e-4, 30.0, -600.0
    i_d, i_q = np.arange(-570.0, 631.0, 20.0), np.arange(-700.0, 701.0, 25.0)
    I_d, I_q = np.meshgrid(i_d, i_q, indexing="ij")
    x, y = I_d - c_d, I_q - c_q
    bump = np.exp(-(x * x + y * y) / (2 * s * s))
    return FluxMap(i_d, i_q, 0.08 + L_d * I_d + b * y * bump, L_q * I_s * np.tanh(I_q / I_s) + a * x * bump, {})


@pytest.mark.parametrize("fmu", ["IpmsmController", "IpmsmPlant"])
def test_far_corner_fold_loads_and_is_refused_once_I_max_reaches_it(fmu_instances, tmp_path, fmu):
    path = tmp_path / "corner.csv"
    write_flux_map(path, far_corner_fold())
    inst, status = _init(fmu_instances, fmu, path, dict(I_max=500.0))
    assert status == WARNING or status == 0, inst.log.text()
    warnings = _map_warnings(inst)
    assert len(warnings) == 1 and "folds at i_d = " in warnings[0], inst.log.text()
    inst, status = _init(fmu_instances, fmu, path, dict(I_max=560.0))
    assert status == 3 and "folds at i_d = " in inst.log.text() and "inside the drive's operating region" in (
        inst.log.text()), inst.log.text()
