"""A flux map's `# key: value` metadata (INTERFACE.md, the map format): the one table of the keys
the readers interpret (key, SI unit, the parameter it gives) and the one rule for their values,
both the FMUs' (fmu_src/machine/flux_map_metadata.cpp). The table reaches Python as data the
build writes from the C++ (scenarios.core.fmu_ranges.map_rules); the rule is restated here in
Python, and tests/data/metadata_values.csv holds both readers to the same verdict on every case.

The rule (docs/maps.md, "Metadata"): a finite number, then optionally the key's SI unit (case
aside), then optionally a comment in parentheses, and nothing else: `0.012`, `0.012 Ohm`, `4 (8
poles)`. Another unit is not converted but refused (`12 mOhm`, `12000 rpm`), as are words
(`4 poles`); a count is a whole number (`pole_pairs: 7.99` is refused, never truncated); a
temperature in K is at least coldest_kelvin (below, it can only be meant in degC).

    metadata_value("R_s_ohm", "0.012 Ohm")   # 0.012
    metadata_value("pole_pairs", "7.99")     # MetadataError: metadata pole_pairs: expected a whole number ...
"""
from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass

from scenarios.core.fmu_ranges import fmu_ranges, map_rules


@dataclass(frozen=True)
class MetadataKey:
    key: str            # "R_s_ohm"
    unit: str           # its SI unit, "" for a number without one
    parameter: str      # the FMUs' (and the drive descriptions') parameter it gives: "R_s"
    checked: bool       # the FMUs warn when the parameter differs from it
    whole_number: bool  # a count


#: the keys only the vehicle side reads (no FMU has their parameter), by the same rule: the
#: rotor's inertia (a drive description's motor.J)
VEHICLE_SIDE_KEYS = (MetadataKey("J_kg_m2", "kg.m2", "J", checked=False, whole_number=False),)


@functools.cache
def metadata_keys() -> dict[str, MetadataKey]:
    """key -> MetadataKey: the FMUs' table, in its order, then VEHICLE_SIDE_KEYS."""
    return {**{k["key"]: MetadataKey(**k) for k in map_rules()["metadata"]}, **{k.key: k for k in VEHICLE_SIDE_KEYS}}


def key_of(parameter: str) -> str:
    """The metadata key that gives a parameter ("lut_u_dc" -> "u_dc_V")."""
    return next(k.key for k in metadata_keys().values() if k.parameter == parameter)


class MetadataError(ValueError):
    """A contract key's value the rule refuses: `key`, what was `expected`, the `text` given."""

    def __init__(self, key: str, expected: str, text: str):
        self.key, self.expected, self.text = key, expected, text
        super().__init__(f"metadata {key}: expected {expected}, got {text[:80]!r} (docs/maps.md, \"Metadata\")")


#: a number as the FMUs' reader takes one (std::from_chars, general format, a leading + allowed)
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")


def _range(k: MetadataKey) -> str:
    """The FMUs' range of the key's parameter, for a message ("; pole_pairs in [1, 100]")."""
    r = fmu_ranges().get(k.parameter)
    return "" if r is None or r.lo is None or r.hi is None else f"; {k.parameter} in [{r.lo:g}, {r.hi:g}]"


def metadata_value(key: str, text: str) -> float | int:
    """The value of a contract key (metadata_keys) by the rule: an int for a count, else a float;
    MetadataError naming the key for a value the rule refuses."""
    k = metadata_keys()[key]
    number = ("an integer (a whole number)" if k.whole_number else "a number") + (f" in {k.unit}" if k.unit else "")
    text = text.strip()
    m = _NUMBER.match(text)
    value = float(m.group(0)) if m else math.nan
    if not math.isfinite(value):
        raise MetadataError(key, f"{number}, finite{_range(k)} (the value "
                            f"{'does not start with a number' if m is None else 'is not finite'})", text)
    rest = text[m.end():].strip()
    if k.unit and rest[:len(k.unit)].lower() == k.unit.lower() and rest[len(k.unit):len(k.unit) + 1] in ("", " ", "\t",
                                                                                                        "("):
        rest = rest[len(k.unit):].strip()
    if rest and not (rest.startswith("(") and rest.endswith(")")):
        raise MetadataError(key, f"{number}{'' if k.unit else ' without a unit'}, optionally followed by a comment in "
                            f"parentheses{' (another unit is not converted)' if k.unit else ''}", text)
    if k.whole_number:
        if value != math.floor(value):
            raise MetadataError(key, f"{number}{_range(k)}", text)
        return int(value)
    if k.unit == "K" and value < map_rules()["coldest_kelvin"]:
        raise MetadataError(key, f"a temperature in K of at least {map_rules()['coldest_kelvin']:g} K (a lower value "
                            "can only be meant in degC)", text)
    return value


def check_metadata(metadata: dict) -> None:
    """Every contract key in `metadata` (key -> text) read by the rule: MetadataError for the
    first it refuses (as the FMUs' reader refuses the map)."""
    for key in metadata_keys():
        if key in metadata:
            metadata_value(key, str(metadata[key]))
