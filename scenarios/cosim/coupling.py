"""The coupling description of the drive (fmu_src/coupling/ipmsm_drive.coupling; its syntax and
semantics are stated in the file): which units, in which order, which output feeds which input,
which external input feeds which inputs. Names only: a master resolves them to value references
from the model descriptions. fmu_src/coupling/coupling.hpp reads the same file in C++, with the
same rules.

    from scenarios.cosim.coupling import DRIVE
    DRIVE.units[0].role, DRIVE.connections[0].source.text   # "plant", "plant.i_d"
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from scenarios.core.paths import located

COUPLING_FILE = located("fmu_src/coupling/ipmsm_drive.coupling")

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


class CouplingError(ValueError):
    """A description that cannot be read: the message names the line and what is wrong."""


@dataclass(frozen=True)
class Port:
    """A variable of a unit, "plant.i_d"."""
    unit: str
    variable: str

    @property
    def text(self) -> str:
        return f"{self.unit}.{self.variable}"


@dataclass(frozen=True)
class Unit:
    role: str               # "plant", "controller"
    model_identifier: str   # the FMU's model identifier


@dataclass(frozen=True)
class Connection:
    source: Port  # an output
    target: Port  # the input it feeds


@dataclass(frozen=True)
class ExternalInput:
    name: str                  # "w_m"
    targets: tuple[Port, ...]  # the inputs it feeds


@dataclass(frozen=True)
class Coupling:
    units: tuple[Unit, ...]  # in the order of initialisation and stepping
    step: float              # s, the default communication step
    connections: tuple[Connection, ...]
    inputs: tuple[ExternalInput, ...]
    text: str                # the description as read (the native master parses the same text)

    @property
    def roles(self) -> tuple[str, ...]:
        return tuple(u.role for u in self.units)

    def unit_index(self, role: str) -> int:
        """Position of the unit in `units` (ValueError if there is none of that role)."""
        return self.roles.index(role)

    @classmethod
    def parse(cls, text: str) -> Coupling:
        r = _Reader()
        for r.line_no, r.raw in enumerate(text.splitlines(), 1):
            r.line(r.raw.split("#", 1)[0].strip())
        if not r.units:
            raise CouplingError("coupling description: no units")
        if r.step == 0.0:
            raise CouplingError("coupling description: no step")
        return cls(tuple(r.units), r.step, tuple(r.connections), tuple(r.inputs), text)

    @classmethod
    def read(cls, path: str | Path = COUPLING_FILE) -> Coupling:
        return cls.parse(Path(path).read_text())


class _Reader:
    """Coupling.parse, line by line (the rules of coupling.hpp)."""

    def __init__(self):
        self.units: list[Unit] = []
        self.step = 0.0
        self.connections: list[Connection] = []
        self.inputs: list[ExternalInput] = []
        self.fed: set[str] = set()  # inputs already fed: each input has one source
        self.line_no, self.raw = 0, ""

    def fail(self, why: str):
        raise CouplingError(f"coupling description, line {self.line_no} ({self.raw.strip()}): {why}")

    def port(self, s: str) -> Port:
        t = s.strip()
        if "." not in t:
            self.fail(f"'{t}' is not ROLE.VARIABLE")
        role, variable = t.split(".", 1)
        if role not in (u.role for u in self.units):
            self.fail(f"no unit '{role}' (declare it with a unit line first)")
        if not _NAME.match(variable):
            self.fail(f"'{variable}' is not a variable name")
        return Port(role, variable)

    def feed(self, p: Port) -> None:
        if p.text in self.fed:
            self.fail(f"{p.text} is fed twice")
        self.fed.add(p.text)

    def line(self, line: str) -> None:
        if not line:
            return
        words = line.split()
        if words[0] == "unit":
            if len(words) != 3:
                self.fail("expected: unit ROLE MODEL_IDENTIFIER")
            if not (_NAME.match(words[1]) and _NAME.match(words[2])):
                self.fail("a role and a model identifier are names")
            if words[1] in (u.role for u in self.units):
                self.fail(f"unit '{words[1]}' declared twice")
            self.units.append(Unit(words[1], words[2]))
        elif words[0] == "step":
            if len(words) != 2:
                self.fail("expected: step SECONDS")
            try:
                self.step = float(words[1])
            except ValueError:
                self.step = math.nan
            if not (math.isfinite(self.step) and self.step > 0):
                self.fail("the step must be a number > 0")
        else:
            if "->" not in line:
                self.fail("expected: unit, step, ROLE.OUTPUT -> ROLE.INPUT or NAME -> ROLE.INPUT, ...")
            source, _, rest = line.partition("->")
            source = source.strip()
            targets = [self.port(item) for item in rest.split(",")] if rest.strip() else []
            if not targets:
                self.fail("no input after '->'")
            if "." in source:
                if len(targets) != 1:
                    self.fail("a connection feeds one input")
                src = self.port(source)
                if src.unit == targets[0].unit:
                    self.fail("a connection joins two units")
                self.feed(targets[0])
                self.connections.append(Connection(src, targets[0]))
            else:
                if not _NAME.match(source):
                    self.fail(f"'{source}' is not an input name")
                if source in (e.name for e in self.inputs):
                    self.fail(f"external input '{source}' declared twice")
                for p in targets:
                    self.feed(p)
                self.inputs.append(ExternalInput(source, tuple(targets)))


#: the drive: IpmsmController + IpmsmPlant
DRIVE = Coupling.read()
