"""The FMUs' own verdict on a flux map: each FMU (IpmsmController, IpmsmPlant, IpmsmDrive)
instantiated and initialised on the map with the machine's parameters, its log kept. The FMUs
are the one source of truth of what they accept; nothing here re-implements their rule."""
from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from pathlib import Path

FMUS = ("IpmsmController", "IpmsmPlant", "IpmsmDrive")
#: fmi2Status names, by value
STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")


@dataclass
class FmuVerdict:
    fmu: str
    accepted: bool
    log: list = field(default_factory=list)   # "status: message" lines of the FMU's logger
    verdict: str = ""                          # "accepted", "accepted with a warning" or "refused"

    def __post_init__(self):
        if not self.verdict:
            warned = any(m.startswith("warning:") for m in self.log)
            self.verdict = ("accepted with a warning" if warned else "accepted") if self.accepted else "refused"

    def warnings(self) -> list[str]:
        return [m for m in self.log if not m.startswith("ok:")]


def verdict(fmu_path: Path, csv: Path, params: dict) -> FmuVerdict:
    """Instantiate the FMU, set flux_map and the parameters it has, initialise; accepted when
    initialisation returns without error. The log is the FMU's, as it wrote it."""
    from fmpy import extract
    from fmpy.fmi2 import (
        FMU2Slave,
        calloc,
        fmi2CallbackAllocateMemoryTYPE,
        fmi2CallbackFreeMemoryTYPE,
        fmi2CallbackFunctions,
        fmi2CallbackLoggerTYPE,
        free,
    )

    from scenarios.cosim.fmu import model_description, set_values

    log = []

    def logger(env, instance, status, category, message):
        # FMI 2.0 passes the message as a printf format (an FMU writes % as %%); it has no
        # arguments here, so formatting it is undoing that escape.
        text = message.decode("utf-8", "replace").replace("%%", "%") if message else ""
        log.append(f"{STATUS[status] if 0 <= status < len(STATUS) else status}: {text}")

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    md = model_description(Path(fmu_path))
    unzipped = extract(str(fmu_path))
    variables = {v.name: v for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName=fmu_path.stem)
    accepted = False
    try:
        fmu.instantiate(callbacks=callbacks, loggingOn=True)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        set_values(fmu, variables, flux_map=str(csv),
                   **{k: v for k, v in params.items() if k in variables and k != "flux_map"})
        try:
            fmu.exitInitializationMode()
            accepted = True
        except Exception:  # fmpy raises Exception on fmi2Error; the FMU's log says why
            pass
        fmu.freeInstance()
    finally:
        shutil.rmtree(unzipped, ignore_errors=True)
    return FmuVerdict(fmu_path.stem, accepted, [m for m in log if "resources in" not in m])


def verdicts(csv: Path, params: dict, build: Path) -> list[FmuVerdict]:
    return [verdict(build / "fmu" / f"{name}.fmu", csv, params) for name in FMUS]
