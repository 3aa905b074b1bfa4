"""The FMUs' own verdict on a flux map: each FMU (IpmsmController, IpmsmPlant, IpmsmDrive)
instantiated and initialised on the map with the machine's parameters, its log kept. The FMUs
are the one source of truth of what they accept; nothing here re-implements their rule."""
from __future__ import annotations

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
    """Instantiate the FMU (the one handle, scenarios.cosim.fmu.Fmu), set flux_map and the
    parameters it has, initialise; accepted when initialisation returns without error. The log
    is the FMU's, as it wrote it, whole."""
    from scenarios.cosim.fmu import CosimError, Fmu

    with Fmu(fmu_path, fmu_path.stem, logging=True, initialise=False, keep_log=None, quiet=True) as f:
        f.set(flux_map=str(csv), **{k: v for k, v in params.items() if k in f.vars and k != "flux_map"})
        try:
            f.exit_initialization()
            accepted = True
        except CosimError:  # fmi2Error: the FMU's log says why
            accepted = False
        log = [f"{STATUS[s] if 0 <= s < len(STATUS) else s}: {m}" for s, _, m in f.messages]
    return FmuVerdict(fmu_path.stem, accepted, [m for m in log if "resources in" not in m])


def verdicts(csv: Path, params: dict, build: Path) -> list[FmuVerdict]:
    return [verdict(build / "fmu" / f"{name}.fmu", csv, params) for name in FMUS]
