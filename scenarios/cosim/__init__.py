"""The drive's FMUs from Python: the one FMU handle (fmu), the IpmsmDrive FMU (drive_fmu, the fast
path) and the reference loop coupling IpmsmController and IpmsmPlant (reference)."""

#: how a run simulates the drive: "drive", the IpmsmDrive FMU; "fmpy", the reference loop
BACKENDS = ("drive", "fmpy")
