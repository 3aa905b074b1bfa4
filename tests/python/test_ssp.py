"""The SSP package of the two-FMU drive (build/ssp/IpmsmControllerPlant.ssp, tools/ssp/make_ssp.py):
fmpy's SSP reader (which validates against the SSP 1.0 schema) reads back every connection of the
coupling description and every parameter of both FMUs with its default, and the FMUs inside are
the ones built."""
from __future__ import annotations

import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.ssp.ssd import read_ssd

from scenarios.cosim.coupling import DRIVE

from conftest import BUILD_FMU, fmu_path

SSP = BUILD_FMU.parent / "ssp" / "IpmsmControllerPlant.ssp"


@pytest.fixture(scope="module")
def ssd():
    if not SSP.exists():
        pytest.fail(f"{SSP} is missing: build it (cmake --build build --target IpmsmControllerPlant_ssp)")
    return read_ssd(str(SSP))


def test_every_connection_of_the_coupling_description(ssd):
    got = {(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in ssd.system.connections}
    want = {(c.source.unit, c.source.variable, c.target.unit, c.target.variable) for c in DRIVE.connections}
    want |= {(None, e.name, t.unit, t.variable) for e in DRIVE.inputs for t in e.targets}
    assert got == want
    assert [c.name for c in ssd.system.connectors] == [e.name for e in DRIVE.inputs]


def test_every_parameter_with_its_default(ssd):
    components = {e.name: e for e in ssd.system.elements}
    assert list(components) == [u.role for u in DRIVE.units]
    for u in DRIVE.units:
        c = components[u.role]
        assert c.source == f"resources/{u.model_identifier}.fmu"
        md = read_model_description(str(fmu_path(u.model_identifier)))
        want = {v.name: (v.type, v.start or "") for v in md.modelVariables if v.causality == "parameter"}
        (binding,) = c.parameterBindings
        (pset,) = binding.parameterValues
        got = {p.name: (p.type, p.value) for p in pset.parameters}
        for name, (t, start) in want.items():
            if t == "Boolean":
                start = "true" if start in ("1", "true") else "false"
            assert got[name] == (t, start), name
        assert set(got) == set(want)
        # every variable a connection or a tool needs is a connector of the component
        names = {k.name for k in c.connectors}
        assert {v.name for v in md.modelVariables if v.causality in ("input", "output", "parameter")} == names


def test_the_fmus_inside_are_the_built_ones_and_the_step_is_the_description_s():
    with zipfile.ZipFile(SSP) as z:
        for u in DRIVE.units:
            assert z.read(f"resources/{u.model_identifier}.fmu") == Path(fmu_path(u.model_identifier)).read_bytes()
        ssd_text = z.read("SystemStructure.ssd").decode()
    assert f'stepSize="{DRIVE.step!r}"' in ssd_text and DRIVE.step == 1e-4
