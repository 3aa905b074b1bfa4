"""Value references are the address an importer stores: every variable of a released FMU keeps
its value reference in later releases (new variables take new ones). Each release's references
are committed (tests/data/value_references_<release>.json, from that release's model
descriptions), with the few a later release had to move named, and why, under `moved_since`."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from conftest import fmu_path

RELEASES = sorted((Path(__file__).resolve().parents[1] / "data").glob("value_references_*.json"))


def current(fmu: Path) -> dict[str, int]:
    with zipfile.ZipFile(fmu) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    return {v.get("name"): int(v.get("valueReference")) for v in root.iter("ScalarVariable")}


def test_every_release_is_recorded():
    assert [p.stem.rpartition("_")[2] for p in RELEASES] == ["0.1.0", "0.2.0"]


@pytest.mark.parametrize("release", RELEASES, ids=lambda p: p.stem.rpartition("_")[2])
@pytest.mark.parametrize("name", ["IpmsmController", "IpmsmPlant", "IpmsmDrive"])
def test_every_released_variable_keeps_its_value_reference(name, release):
    doc = json.loads(release.read_text())
    released, excused = doc["value_references"][name], doc.get("moved_since", {}).get(name, {})
    now = current(fmu_path(name))
    moved = {n: (vr, now.get(n)) for n, vr in released.items() if now.get(n) != vr and n not in excused}
    assert not moved, f"{name}: value references changed since {doc['release']} (name: (then, now)): {moved}"
    assert all(n in now for n in excused), "an excused variable is gone"
