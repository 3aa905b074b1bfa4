"""The flux map's `# key: value` metadata: one table and one rule for both languages. The table is
the FMUs' (fmu_src/machine/flux_map_metadata.cpp), which reaches Python as the data the build
writes (fmu_src/machine/map_rules.json, kept equal to build/map_rules.json here); the rule for a
value is restated in Python (scenarios.maps.metadata) and tests/data/metadata_values.csv holds
both readers to the same verdict on every case (the C++ half: tests/cpp/test_flux_map_bounds.cpp).
Every key of the table, without exception: a value the rule refuses is refused by both FMUs and
by Python naming the key; a value the map states differently from the parameter is warned about
by the FMUs naming the table's parameter where the table says they check it; and a drive over the
map takes the key's value as the table's parameter."""
from __future__ import annotations

import csv
import dataclasses
import json
import math

import pytest

from scenarios.core.boundary import InputError
from scenarios.core.fmu_ranges import MAP_RULES, map_rules
from scenarios.cosim.fmu import CosimError, Fmu
from scenarios.maps.flux_map import DEFAULT_MAP, read_flux_map, write_flux_map
from scenarios.maps.metadata import VEHICLE_SIDE_KEYS, MetadataError, metadata_keys, metadata_value

from conftest import ROOT, fmu_path

KEYS = list(metadata_keys())
#: the keys the FMUs read: the table the build writes (the rest, VEHICLE_SIDE_KEYS, Python's alone)
FMU_KEYS = [k["key"] for k in map_rules()["metadata"]]
CASES = ROOT / "tests" / "data" / "metadata_values.csv"


def _cases():
    with CASES.open(newline="") as f:
        return [(r["key"], r["text"], r["value"]) for r in csv.DictReader(f)]


def _warnings(path, controller_fmu, plant_fmu) -> list[str]:
    out = []
    for fmu in (controller_fmu, plant_fmu):
        with Fmu(fmu, logging=True, flux_map=str(path)) as f:
            out += [m for status, _, m in f.messages if status == 1]
    return out


def _map_with(tmp_path, key, text):
    fmap = read_flux_map(DEFAULT_MAP)
    path = tmp_path / "map.csv"
    write_flux_map(path, dataclasses.replace(fmap, metadata={**fmap.metadata, key: text}))
    return path


def test_the_committed_table_is_the_builds(controller_fmu):
    """fmu_src/machine/map_rules.json is what the build writes from the C++ (write_map_rules)."""
    built = controller_fmu.parent.parent / "map_rules.json"
    assert json.loads(MAP_RULES.read_text()) == json.loads(built.read_text()), \
        "regenerate: cp build/map_rules.json fmu_src/machine/map_rules.json"


@pytest.mark.parametrize("key, text, value", _cases())
def test_python_reads_each_case_as_the_corpus_says(key, text, value):
    if value == "refused":
        with pytest.raises(MetadataError) as e:
            metadata_value(key, text)
        assert e.value.key == key
    else:
        assert metadata_value(key, text) == float(value)


@pytest.mark.parametrize("key, text, value", [c for c in _cases() if c[0] in ("R_s_ohm", "pole_pairs")])
@pytest.mark.parametrize("name", ["IpmsmController", "IpmsmPlant"])
def test_the_fmus_read_each_case_as_python(key, text, value, name, tmp_path):
    """The same cases through the FMUs' reader (a map with the value; the parameter set to it
    where accepted, so that no warning muddles the verdict)."""
    path = _map_with(tmp_path, key, text)
    if value == "refused":
        with pytest.raises(CosimError) as e:
            Fmu(fmu_path(name), flux_map=str(path))
        assert f"metadata {key}:" in str(e.value) and "map.csv" in str(e.value), str(e.value)
        with pytest.raises(InputError) as p:
            read_flux_map(path)
        assert p.value.key == key
    else:
        param = metadata_keys()[key].parameter
        with Fmu(fmu_path(name), logging=True, flux_map=str(path), **{param: float(value)}) as f:
            assert not [m for s, _, m in f.messages if s == 1 and key in m]
        assert read_flux_map(path).number(key) == float(value)


@pytest.mark.parametrize("key", KEYS)
def test_every_key_refused_alike_by_the_fmus_and_python(key, tmp_path):
    """A value in a unit the rule does not take: both FMUs refuse the map naming the key (every key
    they read: all but VEHICLE_SIDE_KEYS), and so does Python's reader (and with it map show, map
    check, run)."""
    path = _map_with(tmp_path, key, "12 furlongs")
    for name in ("IpmsmController", "IpmsmPlant") if key in FMU_KEYS else ():
        # (the FMUs name the value as read, never the file's text: issue 35)
        with pytest.raises(CosimError, match=f"metadata {key}: 12 then 'furlongs'"):
            Fmu(fmu_path(name), flux_map=str(path))
    with pytest.raises(InputError) as e:
        read_flux_map(path)
    assert e.value.key == key and "12 furlongs" in str(e.value)
    assert set(KEYS) == set(FMU_KEYS) | {k.key for k in VEHICLE_SIDE_KEYS}


@pytest.mark.parametrize("key", [k for k, m in metadata_keys().items() if m.checked])
def test_the_fmus_warn_naming_the_tables_parameter(key, tmp_path, controller_fmu, plant_fmu):
    """A key the table says the FMUs check, stated unlike the parameter: warned about, naming it."""
    fmap = read_flux_map(DEFAULT_MAP)
    stated = fmap.number(key, 1.0) * 1.5 + 1.0  # not what the parameter is (the default map's value)
    path = _map_with(tmp_path, key, f"{math.floor(stated) if metadata_keys()[key].whole_number else stated!r}")
    about = [w for w in _warnings(path, controller_fmu, plant_fmu) if f"says {key}:" in w]
    assert about, f"no FMU warns about {key}"
    for w in about:
        assert f"the parameter {metadata_keys()[key].parameter} is" in w, w


@pytest.mark.parametrize("key", KEYS)
def test_a_drive_takes_each_key_as_the_tables_parameter(key, tmp_path):
    """A drive over a map stating the key (a value inside every rule, unlike the default map's):
    the drive's value of the table's parameter is the map's."""
    from scenarios.drives.description import METADATA_RULE, load_drive
    default = read_flux_map(DEFAULT_MAP).number(key, 0.05)
    stated = default + 1 if metadata_keys()[key].whole_number else default * 1.01
    path = _map_with(tmp_path, key, repr(stated))
    (tmp_path / "d.toml").write_text(f'[motor]\nflux_map = "{path}"\n')
    assert load_drive(tmp_path / "d.toml").value(METADATA_RULE[key]) == stated


def test_the_default_map_states_the_fmus_defaults(controller_fmu, plant_fmu):
    """The shipped map's metadata and the FMUs' start values agree: no warning at all."""
    assert _warnings(DEFAULT_MAP, controller_fmu, plant_fmu) == []
