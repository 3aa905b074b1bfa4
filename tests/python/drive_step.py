"""The coupled drive (IpmsmController + IpmsmPlant) in three FMI 2.0 masters, one scenario.

Scenario: a torque step (0 -> 200 N.m at 2 ms) during a speed ramp (2000 -> 8000 r/min over
50 ms) at 100 us, on the default motor; the speed ramp takes the drive from MTPA into field
weakening, where the command is clamped to what is reachable.

Coupling, the same in every master: the drive's coupling description
(fmu_src/coupling/ipmsm_drive.coupling, scenarios.cosim.coupling.DRIVE: Jacobi, what libcosim's
fixed-step algorithm does). The external inputs T_ref and w_m are set before the step from t_k
with their values at t_k (step index k: no floating-point test on the time); u_dc, T_magnet and
T_winding are held at the FMUs' start values.

Masters:
- run_fmpy: this project's reference loop (scenarios.cosim.reference.ReferenceDrive),
  advanced one step at a time; time_grid="ns" passes the times as libcosim does (step_times).
- run_libcosim: libcosim (PyPI libcosimpy), from scenarios/cosim/osp/OspSystemStructure.xml (its
  connections are the description's, test_importers checks it); T_ref and w_m through an
  override manipulator.
- run_container: fmpy's container FMU (fmpy.container_fmu) holding both FMUs with the
  description's connections, driven as one FMU.

Each returns a structured numpy array, one row per step (the values at t_k + h), with the
columns of COLUMNS. `compare` gives the largest difference of each column relative to the
column's largest magnitude.
"""
from __future__ import annotations

import math
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from scenarios.cosim.coupling import DRIVE, Port

H = 1e-4              # s, communication step
N_STEPS = 500         # 50 ms
STEP_AT = 20          # the torque step at t = 2 ms
T_STEP = 200.0        # N.m
RPM_START, RPM_END = 2000.0, 8000.0
U_DC = 355.0          # V

OSP_DIR = Path(__file__).resolve().parents[2] / "scenarios" / "cosim" / "osp"

# the recorded outputs: (FMU, variable); their FMI types come from the model descriptions
RECORDED = [
    ("controller", "T_cmd"), ("controller", "T_max"), ("controller", "i_d_ref"), ("controller", "i_q_ref"),
    ("controller", "u_d_ref"), ("controller", "u_q_ref"), ("controller", "region"),
    ("plant", "i_d"), ("plant", "i_q"), ("plant", "psi_d"), ("plant", "psi_q"), ("plant", "T_e"), ("plant", "P_elec"),
]
COLUMNS = ["k", "T_ref", "w_m"] + [f"{fmu}.{name}" for fmu, name in RECORDED]


def torque(k: int) -> float:
    """T_ref over the step from t_k = k h, N.m."""
    return T_STEP if k >= STEP_AT else 0.0


def speed(k: int) -> float:
    """w_m over the step from t_k, rad/s."""
    return (RPM_START + (RPM_END - RPM_START) * k / N_STEPS) * math.pi / 30.0


def targets(name: str) -> tuple[Port, ...]:
    """The inputs the description's external input `name` feeds."""
    return next(e.targets for e in DRIVE.inputs if e.name == name)


def external(k: int) -> list[tuple[str, str, float]]:
    """The external inputs the scenario drives at step k, to the inputs they feed: (FMU,
    variable, value)."""
    return [(p.unit, p.variable, value) for name, value in (("T_ref", torque(k)), ("w_m", speed(k)))
            for p in targets(name)]


def _table(rows) -> np.ndarray:
    return np.array([tuple(r) for r in rows], dtype=[(c, "f8") for c in COLUMNS])


def _row(k, get):
    return [k, torque(k), speed(k)] + [get(fmu, name) for fmu, name in RECORDED]


def compare(a: np.ndarray, b: np.ndarray) -> dict[str, float]:
    """Per column: max |a - b| / max |a| (0 if both are all zero)."""
    out = {}
    for c in COLUMNS:
        scale = float(np.max(np.abs(a[c])))
        diff = float(np.max(np.abs(a[c] - b[c])))
        out[c] = diff / scale if scale > 0 else diff
    return out


# --- the project's master (fmpy FMU2Slave) ---

def step_times(k: int, time_grid: str = "kh") -> tuple[float, float]:
    """(t_k, h_k) passed to fmi2DoStep. "kh": t_k = k h, h_k = h (this master). "ns": libcosim's
    clock, integer nanoseconds: t_k = (k 100000 ns) / 1e9 s and h_k = t_{k+1} - t_k in double,
    which differs from 1e-4 in its last bits at most steps."""
    if time_grid == "kh":
        return k * H, H
    ns = round(H * 1e9)
    t0, t1 = (k * ns) / 1e9, ((k + 1) * ns) / 1e9
    return t0, t1 - t0


def run_fmpy(controller_fmu: str | Path, plant_fmu: str | Path, time_grid: str = "kh") -> np.ndarray:
    from scenarios.cosim.reference import ReferenceDrive

    rows = []
    with ReferenceDrive(controller_fmu, plant_fmu, h=H, T_ref=torque(0), w_m=speed(0), u_dc=U_DC,
                        clock=None if time_grid == "kh" else (lambda k: step_times(k, time_grid))) as ref:
        held = dict(u_dc=U_DC, T_magnet=ref.held["T_magnet"], T_winding=ref.held["T_winding"])
        for k in range(N_STEPS):
            ref.advance(H, T_ref=torque(k), w_m=speed(k), **held)
            rows.append(_row(k, lambda fmu, name: ref.get(f"{fmu}.{name}")))
    return _table(rows)


# --- libcosim ---

def osp_config(controller_fmu: str | Path, plant_fmu: str | Path, out_dir: str | Path) -> Path:
    """scenarios/cosim/osp/OspSystemStructure.xml with its FMU sources pointed at the given files."""
    ns = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
    ET.register_namespace("", ns)
    tree = ET.parse(OSP_DIR / "OspSystemStructure.xml")
    sources = {"controller": Path(controller_fmu).resolve(), "plant": Path(plant_fmu).resolve()}
    for sim in tree.getroot().iter(f"{{{ns}}}Simulator"):
        sim.set("source", str(sources[sim.get("name")]))
    out = Path(out_dir) / "OspSystemStructure.xml"
    tree.write(out, xml_declaration=True, encoding="utf-8")
    return out


def run_libcosim(controller_fmu: str | Path, plant_fmu: str | Path) -> np.ndarray:
    from fmpy import read_model_description
    from libcosimpy.CosimEnums import CosimExecutionState
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    variables = {key: {v.name: v for v in read_model_description(str(p)).modelVariables}
                 for key, p in (("controller", controller_fmu), ("plant", plant_fmu))}
    with tempfile.TemporaryDirectory(prefix="ipmsm-osp-") as tmp:
        execution = CosimExecution.from_osp_config_file(str(osp_config(controller_fmu, plant_fmu, tmp)))
        index = {key: execution.slave_index_from_instance_name(key) for key in variables}
        assert None not in index.values(), f"the OSP configuration lacks a simulator: {index}"
        manipulator = CosimManipulator.create_override()
        observer = CosimObserver.create_last_value()
        assert execution.add_manipulator(manipulator) is not False
        assert execution.add_observer(observer) is not False
        for fmu, name, value in external(0):
            execution.real_initial_value(index[fmu], variables[fmu][name].valueReference, value)

        def get(fmu, name):
            v = variables[fmu][name]
            read = observer.last_real_values if v.type == "Real" else observer.last_integer_values
            return read(index[fmu], [v.valueReference])[0]

        rows = []
        for k in range(N_STEPS):
            for fmu, name, value in external(k):
                manipulator.slave_real_values(index[fmu], [variables[fmu][name].valueReference], [value])
            if not execution.step():
                raise RuntimeError(f"libcosim: the step from t = {k * H} s failed")
            rows.append(_row(k, get))
        status = execution.status()
        if status.state == CosimExecutionState.ERROR.value:
            raise RuntimeError(f"libcosim: execution error {status.error_code}")
        del execution
        return _table(rows)


# --- fmpy's container FMU ---

def build_container(controller_fmu: str | Path, plant_fmu: str | Path, work_dir: str | Path) -> Path:
    """A container FMU (fmpy.container_fmu) of the two FMUs with the description's connections
    inside; inputs T_ref, w_m (each to the inputs it feeds), outputs "<fmu>.<name>" for RECORDED."""
    import attrs
    from fmpy import read_model_description
    from fmpy.container_fmu.cli import create_container_fmu
    from fmpy.container_fmu.config import Component, Configuration, Connection
    from fmpy.model_description import CoSimulation, DefaultExperiment, ModelDescription, ModelVariable

    comps, variables = {}, {}
    for key, path in (("controller", controller_fmu), ("plant", plant_fmu)):
        md = read_model_description(str(path))
        comps[key] = Component(name=key, filename=Path(path), modelDescription=md)
        variables[key] = {v.name: v for v in md.modelVariables}
    time = ModelVariable(type="Real", variability="continuous", causality="independent", name="time")
    T_ref = ModelVariable(type="Real", variability="continuous", causality="input", name="T_ref",
                          start=repr(torque(0)))
    w_m = ModelVariable(type="Real", variability="continuous", causality="input", name="w_m", start=repr(speed(0)))
    mappings = {v: [(comps[p.unit], variables[p.unit][p.variable]) for p in targets(v.name)] for v in (T_ref, w_m)}
    outputs = []
    for fmu, name in RECORDED:
        kind = variables[fmu][name].type
        v = ModelVariable(type=kind, variability="continuous" if kind == "Real" else "discrete", causality="output",
                          initial="calculated", name=f"{fmu}.{name}")
        outputs.append(v)
        mappings[v] = [(comps[fmu], variables[fmu][name])]
    md = ModelDescription(
        fmiVersion="2.0", modelName="IpmsmDrive", instantiationToken="{6f0e8a52-1d2b-4c3e-9a7f-5b4d3c2e1f00}",
        defaultExperiment=DefaultExperiment(stopTime=str(N_STEPS * H), stepSize=str(H)),
        coSimulation=CoSimulation(fixedInternalStepSize=H),
        modelVariables=[time, T_ref, w_m] + outputs)
    # fmpy 0.3.32 writes a connection's FMI 2 type ("Real") into container.json, where its container
    # binary expects the FMI 3 name ("Float64"), as write_configuration does for the variables:
    # the connectors are passed as copies with that name.
    def connector(fmu, name):
        v = variables[fmu][name]
        return attrs.evolve(v, type={"Real": "Float64", "Integer": "Int32"}.get(v.type, v.type))

    connections = [Connection(comps[c.source.unit], [connector(c.source.unit, c.source.variable)],
                              comps[c.target.unit], [connector(c.target.unit, c.target.variable)])
                   for c in DRIVE.connections]
    config = Configuration(parallelDoStep=False, modelDescription=md, components=list(comps.values()),
                           connections=connections, variableMappings=mappings)
    work_dir = Path(work_dir)
    unzipdir = work_dir / "container"
    unzipdir.mkdir(parents=True, exist_ok=True)
    out = work_dir / "IpmsmDrive.fmu"
    create_container_fmu(config, unzipdir, out)
    return out


def run_container(controller_fmu: str | Path, plant_fmu: str | Path) -> np.ndarray:
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from scenarios.cosim.fmu import get_values, set_values

    with tempfile.TemporaryDirectory(prefix="ipmsm-container-") as tmp:
        container = build_container(controller_fmu, plant_fmu, tmp)
        md = read_model_description(str(container))
        variables = {v.name: v for v in md.modelVariables}
        d = extract(str(container), unzipdir=str(Path(tmp) / "run"))
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="drive")
        fmu.instantiate()
        try:
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            set_values(fmu, variables, T_ref=torque(0), w_m=speed(0))
            fmu.exitInitializationMode()

            def get(f, name):
                return get_values(fmu, variables, f"{f}.{name}")

            rows = []
            t = 0.0  # the container adds up its fixed step: its clock, not k h
            for k in range(N_STEPS):
                set_values(fmu, variables, T_ref=torque(k), w_m=speed(k))
                fmu.doStep(currentCommunicationPoint=t, communicationStepSize=H)
                t += H
                rows.append(_row(k, get))
            fmu.terminate()
        finally:
            fmu.freeInstance()
        return _table(rows)

