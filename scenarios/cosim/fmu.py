"""A thin, fast wrapper around fmpy's FMU2Slave: set and get variables by name, step."""
from __future__ import annotations

import shutil
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


def get_values(fmu: FMU2Slave, variables: dict, *names):
    """The named variables' values (variables: name -> ScalarVariable), each through its type's
    getter: one value for one name, else a list."""
    out = [getattr(fmu, "get" + variables[n].type)([variables[n].valueReference])[0] for n in names]
    return out[0] if len(out) == 1 else out


_AS_TYPE = {"Real": float, "Integer": int, "Boolean": bool, "String": str}


def set_values(fmu: FMU2Slave, variables: dict, **values) -> None:
    """Set variables by name, each through its type's setter, the value converted to that type."""
    for name, value in values.items():
        v = variables[name]
        getattr(fmu, "set" + v.type)([v.valueReference], [_AS_TYPE.get(v.type, lambda x: x)(value)])


class Fmu:
    """One instance of a co-simulation FMU. Parameters go in at construction; then
    step(t, h) with inputs set by name. Use as a context manager (frees the instance)."""

    def __init__(self, path: str | Path, instance_name: str | None = None, logging: bool = False, **parameters):
        self.path = Path(path)
        self.md = read_model_description(str(self.path))
        self._dir = extract(str(self.path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self._dir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=instance_name or self.md.modelName)
        self.fmu.instantiate(loggingOn=logging)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.set(**parameters)
        self.fmu.exitInitializationMode()

    def vr(self, name: str) -> int:
        return self.vars[name].valueReference

    def set(self, **values) -> None:
        set_values(self.fmu, self.vars, **values)

    def get(self, *names):
        return get_values(self.fmu, self.vars, *names)

    def step(self, t: float, h: float) -> None:
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def close(self) -> None:
        try:
            self.fmu.terminate()
        finally:
            self.fmu.freeInstance()
            shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
