"""The drive's FMUs from Python: the one FMU handle (fmu), the IpmsmDrive FMU (drive_fmu, the fast
path) and the reference loop coupling IpmsmController and IpmsmPlant (reference)."""

#: how a run simulates the drive: "drive", the IpmsmDrive FMU; "reference", the reference loop
BACKENDS = ("drive", "reference")
#: other names a command line accepts for a backend: "fmpy", the reference loop's name up to 0.2.0
BACKEND_ALIASES = {"fmpy": "reference"}


def backend_name(name: str) -> str:
    """The backend a name (one of BACKENDS or an alias) stands for; ValueError for another."""
    backend = BACKEND_ALIASES.get(name, name)
    if backend not in BACKENDS:
        raise ValueError(f"backend = {name!r}: one of {', '.join(BACKENDS)} (or {', '.join(BACKEND_ALIASES)})")
    return backend
