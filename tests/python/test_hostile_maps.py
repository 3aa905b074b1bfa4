"""Flux maps and their machines under hostile input (issue 24, docs/inputs.md), as the rest of the
hostile corpus (test_hostile_inputs.py: each command in a child process with an address-space
limit and a timeout; exit 2, one line naming the file and the key; nothing written):

- a map that the FMUs refuse (it is not monotone inside the operating region) is refused when the
  drive loads, with the FMU's own words (where), before any run: the FMUs' rule, asked through
  their initialisation, not a copy of it;
- a thermal network the FMUs refuse (a resistance that turns negative within its fit, a combination
  the schema's per-key rules cannot see) likewise, naming the [thermal] key;
- `map show`'s machine: the map's metadata and the options by the drive schema's rules;
- Motor-CAD exports whose Frequency and Speed cannot give the machine's pole pairs.
"""
from __future__ import annotations

import numpy as np
import pytest
from test_hostile_inputs import assert_refused, cli, drive

from scenarios.maps.flux_map import DEFAULT_MAP, read_flux_map, write_flux_map

#: where the fold is put: well inside the default motor's 500 A circle (i_d <= 0)
FOLD_AT_A = (-100.0, 100.0)


def falling_map(path) -> None:
    """The default map with psi_d falling in i_d between i_d = -100 and -80 A at i_q = 100 A."""
    m = read_flux_map(DEFAULT_MAP)
    j, k = int(np.searchsorted(m.i_d, FOLD_AT_A[0])), int(np.searchsorted(m.i_q, FOLD_AT_A[1]))
    m.psi_d[j, k], m.psi_d[j + 1, k] = m.psi_d[j + 1, k], m.psi_d[j, k]
    write_flux_map(path, m)


@pytest.mark.parametrize("cmd", ["run", "check", "sweep"])
def test_a_map_the_fmus_refuse_inside_the_operating_region_is_refused_at_load(cmd, tmp_path):
    falling_map(tmp_path / "fold.csv")
    d = drive(tmp_path, '[checks]\ncycles = ["UDDS"]\nWh_per_km_max = 500.0\n', name="d.toml",
              flux_map=str(tmp_path / "fold.csv"))
    argv = {"run": ["run", "UDDS", "--drive", str(d)], "check": ["check", str(d)],
            "sweep": ["sweep", "--drive", str(d)]}[cmd]
    r = cli(*argv, "--out", str(tmp_path / "out"))
    # the drive file and key, the FMU that refuses, the map and where: the FMU's own words
    assert_refused(r, d, "motor.flux_map", "IpmsmController", str(tmp_path / "fold.csv"), "i_q = 100 A",
                   "i_d = -100 A", "operating region")
    assert not (tmp_path / "out").exists()
    assert r.wall < 30.0   # before any run (UDDS alone takes minutes)


def test_the_fmus_verdict_is_asked_not_copied(tmp_path):
    """The same fold with I_max below it (outside the operating region): accepted at load (the
    FMUs warn); so the refusal above is the FMUs' rule with the drive's I_max, not a Python one."""
    from scenarios.core.paths import BUILD_DIR
    from scenarios.drives.description import load_drive
    from scenarios.drives.fmu_acceptance import refuse_unless_fmus_accept
    falling_map(tmp_path / "fold.csv")
    d = drive(tmp_path, "I_max = 40.0\n", flux_map=str(tmp_path / "fold.csv"))
    refuse_unless_fmus_accept(load_drive(d), BUILD_DIR)


THERMAL_REFUSED = {
    # r0 + r_n n + r_c c + r_nc n c: each coefficient is any real number, their sum at the fit's
    # corner n = c = 0 is not
    "resistance negative in its fit": ("R_magnet_coolant_0 = -100.0", "thermal.R_magnet_coolant_0",
                                       "R_magnet_coolant", "-100"),
    # each capacity is positive, but 1e-300 J/K makes time constants no step resolves (it ran to 0 K)
    "capacity off by orders of magnitude": ("C_winding = 1e-300", "thermal.C_winding", "C_winding = 1e-300",
                                            "time constants"),
}


@pytest.mark.parametrize("case", THERMAL_REFUSED)
def test_a_thermal_network_the_fmus_refuse_is_refused_at_load(case, tmp_path):
    """Combinations the schema's per-key rules cannot see: the FMU's rule, asked at load."""
    line, key, *words = THERMAL_REFUSED[case]
    d = drive(tmp_path, f"[thermal]\nthermal_model = true\n{line}\n", name="d.toml")
    r = cli("run", "UDDS", "--drive", str(d), "--out", str(tmp_path / "out"))
    assert_refused(r, d, key, "IpmsmPlant", *words)
    assert not (tmp_path / "out").exists()
    assert r.wall < 30.0


MAP_SHOW_METADATA = {
    # metadata line replaced: (new line, key named, words)
    "pole_pairs 1e999": ("# pole_pairs: 4", "# pole_pairs: 1e999", "pole_pairs", "[1, 100]"),
    "pole_pairs 2.5": ("# pole_pairs: 4", "# pole_pairs: 2.5", "pole_pairs", "an integer"),
    "w_m_max 0": ("# w_m_max_rad_s: 1256.63706144", "# w_m_max_rad_s: 0", "w_m_max_rad_s", "(0, 100000]"),
    "R_s nan": ("# R_s_ohm: 0.012", "# R_s_ohm: nan", "R_s_ohm", "a number"),
    "u_dc words": ("# u_dc_V: 355", "# u_dc_V: high", "u_dc_V", "a number"),
    "I_max below the grid": ("# I_max_A: 500", "# I_max_A: 1e-3", "I_max_A", "resolves"),
}


@pytest.mark.parametrize("case", list(MAP_SHOW_METADATA))
def test_map_show_refuses_metadata_a_drive_could_not_carry(case, tmp_path):
    old, new, key, words = MAP_SHOW_METADATA[case]
    text = DEFAULT_MAP.read_text()
    assert old + "\n" in text
    m = tmp_path / "m.csv"
    m.write_text(text.replace(old + "\n", new + "\n"))
    r = cli("map", "show", str(m), "--out", str(tmp_path / "out"))
    assert_refused(r, m, key, words)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("option,value,words", [("--u-dc", "1e308", "(0, 100000]"), ("--I-max", "1e-3", "resolves"),
                                                ("--I-max", "19", "at least 20 A"), ("--u-dc", "0", "(0, 100000]")])
def test_map_show_refuses_options_a_drive_could_not_carry(option, value, words, tmp_path):
    r = cli("map", "show", str(DEFAULT_MAP), option, value, "--out", str(tmp_path / "out"))
    assert_refused(r, "(command line)", option, words)
    assert r.err.count("got") == 1, r.err
    assert not (tmp_path / "out").exists()


MOTORCAD_FREQUENCIES = {
    # (Frequency Hz, Speed r/min) -> the field named
    "NaN frequency": (np.nan, 6000.0, "Frequency"),
    "infinite speed": (400.0, np.inf, "Speed"),
    "zero frequency": (0.0, 6000.0, "Frequency"),
    "negative frequency": (-400.0, 6000.0, "Frequency"),
    "negative speed": (400.0, -6000.0, "Speed"),
    "zero speed": (400.0, 0.0, "Speed"),
    "1e308 Hz at 1e-308 r/min": (1e308, 1e-308, "Frequency"),
    "1e300 Hz": (1e300, 1.0, "Frequency"),
    "1e-300 Hz": (1e-300, 6000.0, "Frequency"),
    "not a whole number of pole pairs": (410.0, 6000.0, "Frequency"),
}


@pytest.mark.parametrize("case", list(MOTORCAD_FREQUENCIES))
@pytest.mark.parametrize("cmd", ["import", "show"])
def test_a_motorcad_export_with_an_impossible_frequency_is_refused(case, cmd, tmp_path):
    import scipy.io as sio
    from test_map_import import motorcad_dq

    from scenarios.maps.flux_map import linear_flux_map
    f, n, key = MOTORCAD_FREQUENCIES[case]
    data = motorcad_dq(linear_flux_map(2e-4, 5e-4, 0.08, 500.0, n=11))
    data.update(Frequency=np.array([[f]]), Speed=np.array([[n]]))
    m = tmp_path / "mc.mat"
    sio.savemat(m, data)
    out = ["--out", str(tmp_path / ("x.csv" if cmd == "import" else "out"))]
    r = cli("map", cmd, str(m), *out)
    assert_refused(r, m, key)
    assert not (tmp_path / "x.csv").exists() and not (tmp_path / "out").exists()


def test_a_motorcad_export_with_a_good_frequency_still_imports(tmp_path):
    """The refusal above is the frequency's: the same export at 400 Hz, 6000 r/min imports (p = 4)."""
    import scipy.io as sio
    from test_map_import import motorcad_dq

    from scenarios.maps.flux_map import linear_flux_map
    m = tmp_path / "mc.mat"
    sio.savemat(m, motorcad_dq(linear_flux_map(2e-4, 5e-4, 0.08, 500.0, n=11)))
    r = cli("map", "import", str(m), "--out", str(tmp_path / "x.csv"))
    assert r.returncode == 0, r.err
    assert "# pole_pairs: 4" in (tmp_path / "x.csv").read_text()


# --- issue 35, "Units dropped": one rule for a metadata value in both readers (docs/maps.md) ---
UNIT_CASES = {
    # case: (line replaced, new line, key named, words)
    "R_s in mOhm": ("# R_s_ohm: 0.012", "# R_s_ohm: 12 mOhm", "R_s_ohm", "another unit is not converted"),
    "top speed in rpm": ("# w_m_max_rad_s: 1256.63706144", "# w_m_max_rad_s: 12000 rpm", "w_m_max_rad_s", "rad/s"),
    "pole pairs 7.99": ("# pole_pairs: 4", "# pole_pairs: 7.99", "pole_pairs", "an integer"),
    "reference temperature in degC": ("# T_winding_ref_K: 293.15", "# T_winding_ref_K: 20", "T_winding_ref_K",
                                      "degC"),
}


def _unit_map(tmp_path, case):
    old, new, key, words = UNIT_CASES[case]
    text = DEFAULT_MAP.read_text()
    assert old + "\n" in text
    m = tmp_path / "m.csv"
    m.write_text(text.replace(old + "\n", new + "\n"))
    return m, key, words


@pytest.mark.parametrize("case", list(UNIT_CASES))
@pytest.mark.parametrize("cmd", ["show", "check", "repair"])
def test_map_commands_refuse_metadata_in_another_unit(case, cmd, tmp_path):
    m, key, words = _unit_map(tmp_path, case)
    out = tmp_path / ("out" if cmd == "show" else "out.csv" if cmd == "repair" else "out")
    r = cli("map", cmd, str(m), "--out", str(out))
    assert_refused(r, m, key, words)
    assert not out.exists()


@pytest.mark.parametrize("case", list(UNIT_CASES))
@pytest.mark.parametrize("cmd", ["run", "check"])
def test_drives_over_metadata_in_another_unit_are_refused(case, cmd, tmp_path):
    """`run` and `check` took 7 from 7.99 and 12 Ohm from 12 mOhm: now the drive is refused at load,
    naming the drive's motor.flux_map, the map and its key."""
    m, key, words = _unit_map(tmp_path, case)
    d = drive(tmp_path, '[checks]\ncycles = ["UDDS"]\nWh_per_km_max = 500.0\n', name="d.toml", flux_map=str(m))
    argv = ["run", "UDDS", "--drive", str(d)] if cmd == "run" else ["check", str(d)]
    r = cli(*argv, "--out", str(tmp_path / "out"))
    assert_refused(r, d, "motor.flux_map", str(m), key, words)
    assert not (tmp_path / "out").exists()
    assert r.wall < 30.0


def test_a_map_with_a_utf8_byte_order_mark_is_read_by_python_as_by_the_fmus(tmp_path):
    """Spreadsheets export UTF-8 with a BOM: the FMUs skip it, and so does Python (map show runs)."""
    from scenarios.cosim.fmu import Fmu

    from conftest import fmu_path
    m = tmp_path / "bom.csv"
    m.write_bytes(b"\xef\xbb\xbf" + DEFAULT_MAP.read_bytes())
    assert read_flux_map(m).metadata == read_flux_map(DEFAULT_MAP).metadata
    for name in ("IpmsmController", "IpmsmPlant"):
        with Fmu(fmu_path(name), flux_map=str(m)):
            pass
    r = cli("map", "check", str(m), "--out", str(tmp_path / "out"))
    assert r.returncode == 0, r.err[-2000:]


@pytest.mark.parametrize("line, key", [("T_winding_max = 180.0", "thermal.T_winding_max"),
                                       ("T_magnet_max = 250.0", "thermal.T_magnet_max")])
def test_a_temperature_limit_below_the_reference_is_refused(line, key, tmp_path):
    """180 meant as degC is 180 K, below T_winding_ref: the car would never move (derated to 0)."""
    d = drive(tmp_path, f"[thermal]\n{line}\n", name="d.toml")
    r = cli("run", "UDDS", "--drive", str(d), "--out", str(tmp_path / "out"))
    assert_refused(r, d, key, "degC")
    assert not (tmp_path / "out").exists()


# --- the importers: every choice refused or named; no metadata the loader refuses is written ---
def _syre_with(tmp_path, **data):
    """The shipped SyR-e motor model with motorModel.data fields replaced."""
    import scipy.io as sio

    from scenarios.core.paths import DATA_DIR
    mat = sio.loadmat(DATA_DIR / "fluxmaps" / "real" / "syre_RAWP.mat", struct_as_record=True)
    rec = mat["motorModel"][0, 0]["data"][0, 0]
    for name, value in data.items():
        rec[name] = np.array(value, dtype=float).reshape(1, -1) if np.ndim(value) else np.array([[value]])
    path = tmp_path / "syre.mat"
    sio.savemat(path, {k: v for k, v in mat.items() if not k.startswith("__")})
    return path


@pytest.mark.parametrize("field, value, words", [("p", 2.5, "whole number"), ("p", 0.0, "positive"),
                                                 ("Vdc", 1e300, "100000"), ("Rs", -1.0, "positive"),
                                                 ("tempCu", -300.0, "absolute zero")])
def test_syre_machine_data_the_loader_would_refuse_is_not_imported(field, value, words, tmp_path):
    m = _syre_with(tmp_path, **{field: value})
    r = cli("map", "import", str(m), "--out", str(tmp_path / "x.csv"))
    key = {"Vdc": "u_dc_V"}.get(field, f"motorModel.data.{field}")
    assert_refused(r, m, key, words)
    assert not (tmp_path / "x.csv").exists()


def test_syre_winding_temperature_at_or_below_zero_degc_is_a_temperature(tmp_path):
    """tempCu = -10 degC is a valid reference (it was dropped: R_s then held at 20 degC)."""
    from scenarios.maps.importer import import_map
    md = import_map(_syre_with(tmp_path, tempCu=-10.0, tempPM=0.0)).metadata
    assert md["T_winding_ref_K"] == pytest.approx(263.15) and md["T_magnet_ref_K"] == pytest.approx(273.15)


@pytest.mark.parametrize("dtype", [bool, np.int32])
def test_a_flux_array_of_logical_or_integer_values_is_refused(dtype, tmp_path):
    import scipy.io as sio
    from test_map_import import motorcad_dq

    from scenarios.maps.flux_map import linear_flux_map
    data = motorcad_dq(linear_flux_map(2e-4, 5e-4, 0.08, 500.0, n=11))
    data["Flux_Linkage_D"] = (np.asarray(data["Flux_Linkage_D"]) * 100).astype(dtype)
    m = tmp_path / "mc.mat"
    sio.savemat(m, data)
    r = cli("map", "import", str(m), "--out", str(tmp_path / "x.csv"))
    assert_refused(r, m, "Flux_Linkage_D", "floating-point")
    assert not (tmp_path / "x.csv").exists()


def test_a_vector_frequency_is_refused_not_reduced_to_its_first_value(tmp_path):
    import scipy.io as sio
    from test_map_import import motorcad_dq

    from scenarios.maps.flux_map import linear_flux_map
    data = motorcad_dq(linear_flux_map(2e-4, 5e-4, 0.08, 500.0, n=11))
    data.update(Frequency=np.array([[400.0, 800.0]]), Speed=np.array([[6000.0]]))
    m = tmp_path / "mc.mat"
    sio.savemat(m, data)
    r = cli("map", "import", str(m), "--out", str(tmp_path / "x.csv"))
    assert_refused(r, m, "Frequency", "2 values")


def test_a_file_holding_two_tools_layouts_is_refused_naming_both(tmp_path):
    import scipy.io as sio

    from scenarios.core.paths import DATA_DIR
    plecs = sio.loadmat(DATA_DIR / "fluxmaps" / "real" / "plecs_prius_lut.mat")
    syre = sio.loadmat(DATA_DIR / "fluxmaps" / "real" / "syre_RAWP.mat")
    both = {k: v for d in (plecs, syre) for k, v in d.items() if not k.startswith("__")}
    m = tmp_path / "both.mat"
    sio.savemat(m, both)
    r = cli("map", "import", str(m), "--out", str(tmp_path / "x.csv"))
    assert_refused(r, m, "variables", "PLECS", "SyR-e")
