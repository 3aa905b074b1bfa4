"""Value references are the address an importer stores: every variable of a released FMU keeps
its value reference in later releases (new variables take new ones). The references of 0.1.0
are committed (tests/data/value_references_0.1.0.json, from that release's model descriptions)."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from conftest import fmu_path

RELEASED = Path(__file__).resolve().parents[1] / "data" / "value_references_0.1.0.json"


def current(fmu: Path) -> dict[str, int]:
    with zipfile.ZipFile(fmu) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    return {v.get("name"): int(v.get("valueReference")) for v in root.iter("ScalarVariable")}


@pytest.mark.parametrize("name", ["IpmsmController", "IpmsmPlant", "IpmsmDrive"])
def test_every_released_variable_keeps_its_value_reference(name):
    released = json.loads(RELEASED.read_text())["value_references"][name]
    now = current(fmu_path(name))
    moved = {n: (vr, now.get(n)) for n, vr in released.items() if now.get(n) != vr}
    assert not moved, f"{name}: value references changed since 0.1.0 (name: (then, now)): {moved}"
