"""The FMUs' own verdict on a drive, at load: the controller and the plant FMU instantiated and
initialised with the drive's flux map, motor and thermal network (scenarios.maps.fmu_verdict), so
that a map they refuse (it folds or falls inside the operating region, its inverse cannot be
built, ...) or a network they refuse (a resistance that turns negative within its fit, ...) ends
the command at load with exit 2, the drive file, the key (`motor.flux_map`, `thermal.<name>`) and
the FMU's own words (where it fails and what to do), before any run. The rule is the FMUs' (fmu_src/machine/
operating_region.*): nothing here re-implements it.
"""
from __future__ import annotations

import os
from pathlib import Path

from scenarios.drives.description import DriveDescription, DriveDescriptionError
from scenarios.maps.fmu_verdict import verdict

#: the FMUs that read the map at initialisation: IpmsmDrive and the SSP/OSP couplings hold these two
FMUS = ("IpmsmController", "IpmsmPlant")
#: what the FMUs' glue appends to a refused initialisation (fmu_src/fmi): true, and no reason
UNDONE = " [initialisation was undone"

_verdicts: dict = {}


def _stamp(path: Path) -> tuple:
    st = os.stat(path)
    return str(path), st.st_mtime_ns, st.st_size


def _reason(log: list[str]) -> str:
    """The FMU's refusal, as it logged it, without the FMI function's name and the glue's coda."""
    errors = [m for m in log if m.startswith(("error:", "fatal:"))] or log or ["(no message)"]
    text = errors[0].split(":", 1)[1].strip()
    if text.startswith("fmi2"):
        text = text.split(":", 1)[-1].strip()
    return text.split(UNDONE, 1)[0]


def _refused_key(drive: DriveDescription, reason: str) -> tuple[str, str]:
    """The drive file's key a refusal names, and what that key must be: the thermal network's
    parameter the FMU names (the file's key for it where it gives one), else the flux map."""
    if not reason.startswith("thermal network"):
        return "motor.flux_map", "a map"
    words = set(reason.split())
    given = [k for k in drive.thermal.given if k != "thermal_model"]
    named = [k for k in given if k in words]
    fitted = [k for k in given if k.rsplit("_", 1)[0] in words]  # R_magnet_coolant_0: R_magnet_coolant's fit
    if named or fitted:
        return f"thermal.{(named or fitted)[0]}", "a thermal network"
    # a refusal of the network as a whole (its time constants, a node's conductances): the keys the
    # file gives are what made it; none given: the network was switched on with the FMU's own values
    keys = ", ".join(f"thermal.{k}" for k in given) or "thermal.thermal_model"
    return keys, "a thermal network (with these keys' values)"


def refuse_unless_fmus_accept(drive: DriveDescription, build: Path) -> None:
    """DriveDescriptionError (file, the key, the FMU's reason) unless every FMU of FMUS
    initialises on the drive's map, motor and thermal network. FMUs missing from `build` are not
    asked (the run says what is missing). Each verdict is kept for the process (same FMU, map and
    parameters)."""
    params_of = {"IpmsmController": drive.controller_params,
                 "IpmsmPlant": lambda: {**drive.plant_params(), **drive.thermal.fmu_params()}}
    for name in FMUS:
        params = params_of[name]()
        fmu = Path(build) / "fmu" / f"{name}.fmu"
        if not fmu.is_file():
            continue
        key = (_stamp(fmu), _stamp(Path(drive.motor.flux_map)), tuple(sorted(params.items())))
        if key not in _verdicts:
            _verdicts[key] = verdict(fmu, Path(drive.motor.flux_map), params)
        v = _verdicts[key]
        if not v.accepted:
            reason = _reason(v.log)
            key, what = _refused_key(drive, reason)
            raise DriveDescriptionError(drive.source, key,
                                        f"{what} the {name} FMU accepts with this motor; it refuses it: {reason}")


def load_accepted(path: Path | None, build: Path) -> DriveDescription:
    """The drive description at `path` (None: the default drive), refused (DriveDescriptionError:
    exit 2) unless the FMUs in `build` accept its map, motor and thermal network."""
    from scenarios.drives.description import load_drive
    drive = load_drive(path)
    refuse_unless_fmus_accept(drive, build)
    return drive
