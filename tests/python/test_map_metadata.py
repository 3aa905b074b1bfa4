"""The flux map's `# key: value` metadata -> parameter table, written once per language: Python's
(scenarios.maps.machine.METADATA_KEYS, which the drive descriptions, `map show` and `map check`
read) and the FMUs' (fmu_src/machine/flux_map_metadata.cpp, which IpmsmController and IpmsmPlant
check their parameters against). Each key of Python's table is stated in a map with a value other
than the parameter's: an FMU that checks the key must warn naming Python's parameter for it; only
the keys the FMUs are known not to check may pass silently. A key added, renamed or mapped to
another parameter on one side only fails here. (Skipped where scenarios.maps.machine does not
exist yet: it comes with the map tools' branch.)"""
from __future__ import annotations

import dataclasses

import pytest

from scenarios.cosim.fmu import Fmu
from scenarios.maps import machine
from scenarios.maps.flux_map import DEFAULT_MAP, read_flux_map, write_flux_map

#: keys the scenarios read but the FMUs do not check against a parameter: the current limit must
#: lie inside the grid (checked on its own), the DC voltage and k_u are the tables' design point,
#: the top speed is the vehicle side's
NOT_CHECKED_BY_THE_FMUS = {"I_max_A", "u_dc_V", "k_u", "w_m_max_rad_s"}


def _warnings(path, controller_fmu, plant_fmu) -> list[str]:
    out = []
    for fmu in (controller_fmu, plant_fmu):
        with Fmu(fmu, logging=True, flux_map=str(path)) as f:
            out += [m for status, _, m in f.messages if status == 1]
    return out


@pytest.mark.parametrize("parameter, key", list(machine.METADATA_KEYS.items()))
def test_the_fmus_map_each_key_to_pythons_parameter(parameter, key, tmp_path, controller_fmu, plant_fmu):
    fmap = read_flux_map(DEFAULT_MAP)
    stated = fmap.number(key, 1.0) * 1.5 + 1.0  # not what the parameter is (the default map's value)
    metadata = {**fmap.metadata, key: f"{int(stated) if key == 'pole_pairs' else stated!r}"}
    path = tmp_path / "map.csv"
    write_flux_map(path, dataclasses.replace(fmap, metadata=metadata))
    about = [w for w in _warnings(path, controller_fmu, plant_fmu) if f"says {key}:" in w]
    if key in NOT_CHECKED_BY_THE_FMUS:
        assert about == [], about
    else:
        assert about, f"no FMU warns about {key}"
        for w in about:
            assert f"the parameter {parameter} is" in w, w


def test_the_default_map_states_the_fmus_defaults(controller_fmu, plant_fmu):
    """The shipped map's metadata and the FMUs' start values agree: no warning at all."""
    assert _warnings(DEFAULT_MAP, controller_fmu, plant_fmu) == []
