"""Tests of the FMI 2.0 glue (fmu_src/fmi/) through the ToyLag test FMU (tests/toy_fmu/).

The FMU is taken from $IPMSM_FMU_DIR/ToyLag.fmu, by default <repo>/build/fmu/ToyLag.fmu; the tests
are skipped if it has not been built (cmake --build build --target ToyLag_fmu).
fmpy's FMU2Slave raises FMICallException for any status above fmi2Warning; the tests use that.
"""

import ctypes
import math
import os
import pathlib
import shutil
import zipfile

import fmpy
import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2CoSimulation,
    fmi2Discard,
    fmi2DoStepStatus,
    fmi2Error,
    fmi2FMUstate,
    fmi2LastSuccessfulTime,
    fmi2ModelExchange,
    fmi2OK,
    fmi2PendingStatus,
    fmi2Terminated,
    fmi2True,
    fmi2ValueReference,
    fmi2Warning,
)
from fmpy.validation import validate_fmu

from scenarios.cosim.fmu import get_values, set_values

from conftest import same

REPO = pathlib.Path(__file__).resolve().parents[2]
FMU_DIR = pathlib.Path(os.environ.get("IPMSM_FMU_DIR", REPO / "build" / "fmu"))
FMU = FMU_DIR / "ToyLag.fmu"

pytestmark = pytest.mark.skipif(
    not FMU.is_file(),
    reason=f"{FMU} has not been built (cmake --build build --target ToyLag_fmu, or set IPMSM_FMU_DIR)",
)


@pytest.fixture(scope="module")
def md():
    return read_model_description(str(FMU))


@pytest.fixture(scope="module")
def unzipdir(tmp_path_factory):
    return pathlib.Path(extract(str(FMU), unzipdir=str(tmp_path_factory.mktemp("ToyLag"))))


class Log:
    """A logger callback that keeps (status, category, message) of every message."""

    def __init__(self, with_logger=True):
        self.records = []
        self.callbacks = fmi2CallbackFunctions()
        self._logger = fmi2CallbackLoggerTYPE(self._log)
        if with_logger:
            self.callbacks.logger = self._logger
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)

    def _log(self, env, instance, status, category, message):
        # the message is a printf format: the glue doubles every '%'
        self.raw = message.decode()
        self.records.append((status, category.decode(), self.raw.replace("%%", "%")))

    def messages(self, status=None, category=None):
        return [m for s, c, m in self.records
                if (status is None or s == status) and (category is None or c == category)]

    def errors(self):
        return "\n".join(self.messages(fmi2Error))

    def clear(self):
        self.records.clear()


class Toy:
    """One ToyLag instance driven through fmpy's low-level FMU2Slave; resource_uri (bytes or None)
    replaces the resources URI that fmpy would pass."""

    def __init__(self, md, unzipdir, name="toy", logging_on=False, resource_uri=...):
        self.vars = {v.name: v for v in md.modelVariables}
        self.log = Log()
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipdir),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        if resource_uri is ...:
            self.fmu.instantiate(callbacks=self.log.callbacks, loggingOn=logging_on)
        else:
            self.fmu.component = self.fmu.fmi2Instantiate(name.encode(), fmi2CoSimulation, md.guid.encode(),
                                                          resource_uri, ctypes.byref(self.log.callbacks), 0,
                                                          logging_on)
            assert self.fmu.component is not None
        self.t = 0.0
        self.freed = False

    def vr(self, name):
        return self.vars[name].valueReference

    def set(self, **values):
        set_values(self.fmu, self.vars, **values)

    def get(self, name):
        value = get_values(self.fmu, self.vars, name)
        return value.decode() if self.vars[name].type == "String" else value

    def init(self, **params):
        self.fmu.setupExperiment(startTime=0.0)
        self.set(**params)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.t = 0.0

    def step(self, h=0.01):
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        self.t += h

    def outputs(self):
        return (tuple(self.fmu.getReal([self.vr(n) for n in ("y", "angle", "T_out", "y_prev")]))
                + (self.get("steps"), self.get("held")))

    def run(self, n, h=0.01, u=lambda i: math.sin(0.3 * i), w=lambda i: 0.5 * i):
        rows = []
        for i in range(n):
            self.set(u=u(i), w=w(i))
            self.step(h)
            rows.append(self.outputs())
        return rows

    def free(self):
        if not self.freed:
            self.fmu.freeInstance()
            self.freed = True


@pytest.fixture
def toys(md, unzipdir):
    made = []

    def make(**kw):
        toy = Toy(md, kw.pop("unzipdir", unzipdir), **kw)
        made.append(toy)
        return toy

    yield make
    for toy in made:
        toy.free()


def refused(toy, call, *args, status=fmi2Error, match=None, **kwargs):
    """Assert that call(*args, **kwargs) fails with `status` and that the log says `match`."""
    toy.log.clear()
    with pytest.raises(FMICallException) as e:
        call(*args, **kwargs)
    assert e.value.status == status, f"{e.value.function} returned {e.value.status}, expected {status}"
    if match is not None:
        text = "\n".join(toy.log.messages())
        assert match in text, f"log lacks {match!r}:\n{text}"
    return e.value


# --- the package ---

def test_validate_and_dump(capsys):
    assert validate_fmu(str(FMU)) == []
    fmpy.dump(str(FMU))
    out = capsys.readouterr().out
    assert "ToyLag" in out and "Co-Simulation" in out


def test_package_layout():
    names = set(zipfile.ZipFile(FMU).namelist())
    for n in ("modelDescription.xml", "binaries/linux64/ToyLag.so", "resources/offset.txt", "documentation/index.html"):
        assert n in names


def test_model_description(md):
    cs = md.coSimulation
    assert cs.modelIdentifier == "ToyLag" and md.generationTool == "ipmsm-fmu"
    assert cs.canHandleVariableCommunicationStepSize and cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    assert not cs.canBeInstantiatedOnlyOncePerProcess and cs.canNotUseMemoryManagementFunctions
    assert not cs.needsExecutionTool
    assert md.defaultExperiment.startTime == "0" and float(md.defaultExperiment.stopTime) == 1.0
    assert float(md.defaultExperiment.stepSize) == 0.01
    assert [c.name for c in md.logCategories] == ["logEvents", "logStatusWarning", "logStatusDiscard",
                                                  "logStatusError", "logStatusFatal", "logAll"]
    units = {u.name: u for u in md.unitDefinitions}
    rpm = units["rad/s"].displayUnits[0]
    assert rpm.name == "rpm" and math.isclose(rpm.factor, 60 / (2 * math.pi), rel_tol=1e-15)
    degc = units["K"].displayUnits[0]
    assert degc.name == "degC" and degc.offset == -273.15 and degc.factor == 1
    assert units["V"].baseUnit.kg == 1 and units["V"].baseUnit.A == -1
    v = {x.name: x for x in md.modelVariables}
    assert [x.valueReference for x in md.modelVariables] == list(range(len(md.modelVariables)))
    assert all(x.description for x in md.modelVariables)
    assert v["tau"].start == "0.1" and v["T_amb"].start == "293.15" and v["u"].min == "-100"
    assert v["n_sub"].max == "10000000" and v["fault"].max == "5"  # xs:int, not "1e+07"
    assert v["w"].displayUnit == "rpm" and v["T_out"].displayUnit == "degC"
    assert v["y"].causality == "output" and v["y"].initial == "calculated" and v["y"].start is None
    outputs = [x for x in md.modelVariables if x.causality == "output"]
    assert [u.variable for u in md.outputs] == outputs
    assert [u.variable for u in md.initialUnknowns] == outputs


# The exported symbols, the shared libraries and glibc versions the library needs: checked for
# every FMU add_fmu() builds, ToyLag included, in test_conformance.py.


# --- results ---

def test_simulate_matches_closed_form():
    u, k, tau, y0, w = 2.0, 1.5, 0.2, 0.5, 3.0
    r = simulate_fmu(str(FMU), start_values={"u": u, "k": k, "tau": tau, "y0": y0, "w": w},
                     stop_time=1.0, output_interval=0.01, output=["y", "angle", "T_out"])
    t = r["time"]
    assert len(t) == 101 and t[-1] == pytest.approx(1.0)
    expected = k * u + (y0 - k * u) * np.exp(-t / tau)
    np.testing.assert_allclose(r["y"], expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r["angle"], w * t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r["T_out"], 293.15 + expected, rtol=0, atol=1e-9)


def test_hold_and_substeps(toys):
    a = toys()
    a.init(n_sub=7, tau=0.05)
    a.set(u=1.0, hold=True)
    a.step()
    assert a.get("y") == 0.0 and a.get("held") == 1
    a.set(hold=False)
    a.step(0.02)
    assert a.get("y") == pytest.approx(1 - math.exp(-0.02 / 0.05), abs=1e-14)
    assert not a.get("held") and a.get("steps") == 2


# --- refused values ---

@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_nonfinite_input_refused_and_instance_stays_usable(toys, bad):
    a, ref = toys(), toys(name="ref")
    a.init()
    ref.init()
    a.set(u=0.7)
    a.step()
    e = refused(a, a.set, match="u = ", u=bad)
    assert e.function == "fmi2SetReal"
    assert "fmi2SetReal" in a.log.errors() and "not a finite number" in a.log.errors()
    assert a.get("u") == 0.7
    assert all(math.isfinite(x) for x in a.outputs()[:4])
    ref.set(u=0.7)
    ref.step()
    assert same(a.run(20), ref.run(20))


def test_out_of_range_refused(toys):
    a = toys()
    refused(a, a.set, match="out of range: it must be [-100, 100]", u=100.5)
    refused(a, a.set, match="it must be > 0", tau=0.0)
    refused(a, a.set, tau=-1.0)
    refused(a, a.set, match="n_sub", n_sub=0)
    refused(a, a.set, fault=6)
    refused(a, a.set, T_amb=0.0)
    a.set(u=100.0, tau=1e-9, n_sub=10000000)  # the bounds themselves are fine
    # all or nothing: one bad value in a call keeps every old value
    refused(a, a.fmu.setReal, [a.vr("u"), a.vr("k")], [1.0, 99.0])
    a.fmu.enterInitializationMode()
    assert a.get("u") == 100.0 and a.get("k") == 1.0


def test_unknown_value_reference_and_wrong_type(toys):
    a = toys()
    a.init()
    refused(a, a.fmu.getReal, [999], match="unknown value reference 999")
    refused(a, a.fmu.setReal, [999], [1.0], match="unknown value reference 999")
    refused(a, a.fmu.getInteger, [a.vr("u")], match="is the Real u, not an Integer")
    refused(a, a.fmu.setBoolean, [a.vr("u")], [True], match="not a Boolean")
    refused(a, a.fmu.getString, [a.vr("tau")], match="not a String")
    refused(a, a.fmu.setInteger, [a.vr("hold")], [1], match="not an Integer")


def test_null_arrays(toys):
    a = toys()
    a.init()
    c = a.fmu.component
    refused(a, a.fmu.fmi2GetReal, c, None, 1, None, match="NULL")
    refused(a, a.fmu.fmi2SetReal, c, None, 1, None, match="NULL")
    vr = (fmi2ValueReference * 1)(a.vr("u"))
    refused(a, a.fmu.fmi2GetReal, c, vr, 1, None, match="NULL")
    assert a.fmu.fmi2GetReal(c, None, 0, None) == fmi2OK  # nvr = 0: a valid no-op
    assert a.fmu.fmi2SetReal(c, None, 0, None) == fmi2OK
    assert a.fmu.fmi2GetString(c, None, 0, None) == fmi2OK


def test_outputs_and_locals_cannot_be_set(toys):
    a = toys()
    refused(a, a.set, match="y is an output", y=1.0)
    a.init()
    refused(a, a.set, match="y_prev is a local", y_prev=1.0)
    refused(a, a.set, steps=3)
    refused(a, a.set, held=True)


def test_fixed_parameters_refused_after_initialisation(toys):
    a = toys()
    a.init(tau=0.2)
    refused(a, a.set, match="tau is a fixed parameter", tau=0.3)
    refused(a, a.set, match="offset_file is a fixed parameter", offset_file="offset.txt")
    assert a.get("tau") == 0.2
    a.set(u=1.0, k=2.0)  # an input and a tunable parameter
    a.step()
    assert a.get("y") == pytest.approx(2.0 * (1 - math.exp(-0.01 / 0.2)), abs=1e-15)


def test_strings(toys):
    a = toys()
    a.set(offset_file="a file with spaces & <xml>")
    a.fmu.enterInitializationMode()
    assert a.get("offset_file") == "a file with spaces & <xml>"
    refused(a, a.fmu.setString, [a.vr("offset_file")], [None], match="NULL string")
    assert a.fmu.getString([a.vr("offset_file"), a.vr("offset_file")]) == [b"a file with spaces & <xml>"] * 2


# --- the state machine ---

def test_calls_in_the_wrong_state_are_refused(toys):
    a = toys()
    refused(a, a.fmu.doStep, 0.0, 0.01, match="fmi2DoStep is not allowed in state instantiated")
    refused(a, a.fmu.getReal, [a.vr("y")], match="fmi2GetReal is not allowed in state instantiated")
    refused(a, a.fmu.exitInitializationMode, match="state instantiated")
    refused(a, a.fmu.terminate, match="fmi2Terminate is not allowed in state instantiated")
    refused(a, a.fmu.getRealStatus, fmi2LastSuccessfulTime, match="state instantiated")
    a.fmu.setupExperiment(startTime=0.0)
    a.fmu.enterInitializationMode()
    refused(a, a.fmu.enterInitializationMode, match="state initializationMode")
    refused(a, a.fmu.doStep, 0.0, 0.01, match="fmi2DoStep is not allowed in state initializationMode")
    refused(a, a.fmu.setupExperiment, match="fmi2SetupExperiment is not allowed")
    a.fmu.exitInitializationMode()
    a.step()
    a.fmu.terminate()
    refused(a, a.fmu.doStep, a.t, 0.01, match="state terminated")
    refused(a, a.set, match="fmi2SetReal is not allowed in state terminated", u=1.0)
    assert a.get("steps") == 1  # values can still be read
    a.fmu.reset()
    refused(a, a.fmu.doStep, 0.0, 0.01, match="state instantiated")
    a.init()
    a.step()
    assert a.get("steps") == 1


@pytest.mark.parametrize("t, h, match", [
    (0.0, 0.0, "communicationStepSize = 0 must be"),
    (0.0, -0.01, "must be a finite number > 0"),
    (0.0, math.nan, "communicationStepSize = nan"),
    (0.0, math.inf, "communicationStepSize = inf"),
    (math.nan, 0.01, "currentCommunicationPoint = nan"),
    (0.5, 0.01, "previous step ended at 0"),
])
def test_bad_steps_refused(toys, t, h, match):
    a = toys()
    a.init()
    refused(a, a.fmu.doStep, t, h, match=match)
    assert a.get("steps") == 0
    a.step()
    assert a.get("steps") == 1


# --- time: a step continues where the last one ended ---

WALL_CLOCK = 1.7e9  # s: a start time of masters synchronised to the Unix epoch


@pytest.mark.parametrize("start, gap", [
    (0.0, 1e-10),          # a tenth of a nanosecond late (the former tolerance was 1 ns there)
    (0.0, -0.005),         # half a step back: overlapping the last step
    (WALL_CLOCK, 0.01),    # one whole step skipped (the former tolerance was 1.7 s there)
    (WALL_CLOCK, -0.005),
])
def test_a_communication_point_that_does_not_follow_the_last_is_refused(toys, start, gap):
    a = toys()
    a.fmu.setupExperiment(startTime=start)
    a.fmu.enterInitializationMode()
    a.fmu.exitInitializationMode()
    h = 0.01
    a.fmu.doStep(start, h)
    t = start + h
    before = a.outputs()
    e = refused(a, a.fmu.doStep, t + gap, h, match="previous step ended at")
    assert e.function == "fmi2DoStep"
    assert same([a.outputs()], [before]) and a.get("steps") == 1  # nothing happened
    assert a.fmu.getRealStatus(fmi2LastSuccessfulTime) == t
    a.fmu.doStep(t, h)  # the instance stays usable
    assert a.get("steps") == 2


@pytest.mark.parametrize("start", [0.0, -3.3, 12345.678, WALL_CLOCK])
@pytest.mark.parametrize("h", [1e-5, 1e-4, 1.0 / 3.0])
def test_masters_that_count_their_steps_are_accepted(toys, start, h):
    """The tolerance is as tight as rounding allows but no tighter: masters that compute
    t_k = start + k h (numpy.linspace) rather than adding up h are never refused."""
    a = toys()
    a.fmu.setupExperiment(startTime=start)
    a.set(tau=1e6)  # no "longer than tau" warning
    a.fmu.enterInitializationMode()
    a.fmu.exitInitializationMode()
    n = 3000
    counted = start + np.arange(n) * h
    grid = np.linspace(start, start + n * h, n + 1)
    for t in counted:
        a.fmu.doStep(float(t), h)
    b = toys(name="b")
    b.fmu.setupExperiment(startTime=start)
    b.set(tau=1e6)
    b.fmu.enterInitializationMode()
    b.fmu.exitInitializationMode()
    for k in range(n):  # a time grid stepped by its own differences
        b.fmu.doStep(float(grid[k]), float(grid[k + 1] - grid[k]))
    assert a.get("steps") == n and b.get("steps") == n


# --- model failures ---

@pytest.mark.parametrize("fault, match", [
    (1, "fault 1: fmi::Error from do_step"),
    (2, "fault 2: std::runtime_error from do_step"),
    (3, "unknown exception"),
    (4, "the model computed y = nan"),
    (5, "out of memory"),  # issue 16: undone like any failure, the instance stays usable
])
def test_model_failure_is_undone(toys, fault, match):
    a, ref = toys(), toys(name="ref")
    a.init(tau=0.3)
    ref.init(tau=0.3)
    first = a.run(5)
    assert same(first, ref.run(5))
    before = a.outputs()
    a.set(fault=fault)
    refused(a, a.fmu.doStep, a.t, 0.01, match=match)
    assert "was undone" in a.log.errors() and "fmi2DoStep" in a.log.errors()
    assert same([a.outputs()], [before])  # nothing of the failed step is left, no NaN
    a.set(fault=0)
    assert same(a.run(10), ref.run(10))


def test_failed_initialisation_can_be_corrected(toys):
    a = toys(logging_on=True)
    a.fmu.setupExperiment(startTime=0.0)
    a.set(offset_file="missing.txt", y0=1.0)
    a.fmu.enterInitializationMode()
    refused(a, a.fmu.exitInitializationMode, match="cannot read a number from")
    assert "initialisation was undone" in a.log.errors()
    a.set(offset_file="offset.txt")
    a.fmu.exitInitializationMode()
    assert a.get("y") == 1.25
    assert any("offset 0.25" in m for m in a.log.messages(fmi2OK, "logEvents"))


def test_outputs_in_initialization_mode_are_those_after_it(toys):
    """Outputs are InitialUnknowns: in Initialization Mode a Get of one answers with the value it
    will have after fmi2ExitInitializationMode, for the values set so far; if that cannot be
    computed the Get fails with the reason, and nothing is logged as if initialised."""
    a = toys(logging_on=True)
    a.fmu.setupExperiment(startTime=0.0)
    a.fmu.enterInitializationMode()
    assert a.get("y") == 0.0 and a.get("T_out") == 293.15
    a.set(y0=1.5, T_amb=300.0)
    assert a.get("y") == 1.5 and a.get("T_out") == 301.5
    a.set(offset_file="missing.txt")
    a.log.clear()
    refused(a, a.fmu.getReal, [a.vr("y")], match="cannot be computed in Initialization Mode")
    assert a.get("y0") == 1.5  # parameters and inputs read as set
    a.set(offset_file="offset.txt")
    assert a.get("y") == 1.75
    assert not a.log.messages(fmi2OK, "logEvents")  # the model's "offset 0.25 from" is muted here
    a.fmu.exitInitializationMode()
    assert a.get("y") == 1.75 and a.get("T_out") == 301.75
    assert any("offset 0.25" in m for m in a.log.messages(fmi2OK, "logEvents"))


# --- reset, free, instances ---

def test_reset_twice_then_run_again(toys):
    a, ref = toys(), toys(name="ref")
    a.init(tau=0.05, k=3.0)
    a.run(10)
    a.fmu.reset()
    a.fmu.reset()
    assert a.fmu.fmi2Reset(a.fmu.component) == fmi2OK
    a.init(y0=2.0)
    ref.init(y0=2.0)
    assert a.get("tau") == 0.1 and a.get("k") == 1.0  # start values again
    assert same(a.run(30), ref.run(30))


def test_free_without_terminate(toys):
    for stop_after in ("instantiate", "init", "step"):
        a = toys()
        if stop_after != "instantiate":
            a.init()
        if stop_after == "step":
            a.run(3)
            a.fmu.getFMUstate()  # a state never freed: freeInstance takes care of it
        a.free()


def test_two_instances_interleaved(toys):
    a, b = toys(name="a"), toys(name="b")
    c = toys(name="c")  # other parameters, interleaved too
    solo_ab, solo_c = toys(name="solo_ab"), toys(name="solo_c")
    for x in (a, b, solo_ab):
        x.init(tau=0.07)
    for x in (c, solo_c):
        x.init(tau=0.5, k=-2.0, n_sub=3)
    rows = {x: [] for x in (a, b, c)}
    for i in range(40):
        for x in (a, c, b):
            x.set(u=math.sin(0.3 * i), w=0.5 * i)
            x.step()
            rows[x].append(x.outputs())
    assert same(rows[a], rows[b])
    assert same(rows[a], solo_ab.run(40))
    assert same(rows[c], solo_c.run(40))
    assert not same(rows[a], rows[c])


def test_instantiate_refusals(md, unzipdir):
    log = Log()
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipdir), modelIdentifier="ToyLag")
    uri = (unzipdir / "resources").as_uri().encode()
    cb = ctypes.byref(log.callbacks)
    assert fmu.fmi2Instantiate(b"x", fmi2CoSimulation, b"{wrong}", uri, cb, 0, 0) is None
    assert "GUID {wrong} does not match" in log.errors()
    assert fmu.fmi2Instantiate(b"x", fmi2ModelExchange, md.guid.encode(), uri, cb, 0, 0) is None
    assert "fmuType must be fmi2CoSimulation" in log.errors()
    assert fmu.fmi2Instantiate(b"", fmi2CoSimulation, md.guid.encode(), uri, cb, 0, 0) is None
    assert fmu.fmi2Instantiate(None, fmi2CoSimulation, md.guid.encode(), uri, cb, 0, 0) is None
    assert fmu.fmi2Instantiate(b"x", fmi2CoSimulation, None, uri, cb, 0, 0) is None
    # NULL callbacks, or no logger in them: the instance works and logs nothing
    for callbacks in (None, ctypes.byref(Log(with_logger=False).callbacks)):
        c = fmu.fmi2Instantiate(b"x", fmi2CoSimulation, md.guid.encode(), uri, callbacks, 0, 1)
        assert c is not None
        with pytest.raises(FMICallException):
            fmu.fmi2DoStep(c, 0.0, 0.01, fmi2True)  # an error with nobody to tell
        assert fmu.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0) == fmi2OK
        fmu.fmi2FreeInstance(c)
    fmu.freeLibrary()


# --- resources ---

def test_resource_path_with_spaces(toys, unzipdir, tmp_path):
    spaced = tmp_path / "a dir with spaces" / "Toy Lag 100%"
    shutil.copytree(unzipdir, spaced)
    a = toys(unzipdir=spaced)
    a.init(offset_file="offset.txt", y0=1.0)
    assert a.get("y") == 1.25


@pytest.mark.parametrize("form", ["file:///", "file:/", "file://localhost/", "plain", "trailing-slash"])
def test_resource_uri_forms(toys, unzipdir, tmp_path, form):
    spaced = tmp_path / "res dir" / "Toy Lag"
    shutil.copytree(unzipdir, spaced)
    res = str(spaced / "resources")
    quoted = res.replace("%", "%25").replace(" ", "%20")
    uri = {"file:///": "file://" + quoted, "file:/": "file:" + quoted, "file://localhost/": "file://localhost" + quoted,
           "plain": res, "trailing-slash": "file://" + quoted + "/"}[form]
    a = toys(resource_uri=uri.encode())
    a.init(offset_file="offset.txt")
    assert a.get("y") == 0.25


@pytest.mark.parametrize("uri", [None, b"http://example.com/resources", b"file://otherhost/r", b"file:///bad%zzescape",
                                 b"relative/dir"])
def test_unusable_resource_uri_means_no_resources(toys, uri):
    a = toys(resource_uri=uri)
    a.set(offset_file="offset.txt")
    a.fmu.enterInitializationMode()
    refused(a, a.fmu.exitInitializationMode, match="no resources directory")
    a.set(offset_file="")
    a.fmu.exitInitializationMode()  # the model needs no resources now


# --- FMU states ---

def test_get_set_fmu_state_is_bit_identical(toys):
    a = toys()
    a.init(tau=0.04, n_sub=2)
    a.run(5)
    state = a.fmu.getFMUstate()
    t = a.t
    first = a.run(15)
    a.fmu.setFMUstate(state)
    a.t = t
    assert a.fmu.getRealStatus(fmi2LastSuccessfulTime) == t
    assert same(a.run(15), first)
    # fmi2GetFMUstate into an existing state reuses it, with the new content
    again = fmi2FMUstate(state.value)
    t2 = a.t
    assert a.fmu.fmi2GetFMUstate(a.fmu.component, ctypes.byref(again)) == fmi2OK
    assert again.value == state.value
    later = a.run(3)
    a.fmu.setFMUstate(state)
    a.t = t2
    assert same(a.run(3), later)
    dangling = fmi2FMUstate(state.value)
    a.fmu.freeFMUstate(state)
    assert state.value is None
    refused(a, a.fmu.setFMUstate, dangling, match="not one of this instance's")
    refused(a, a.fmu.serializeFMUstate, dangling, match="not one of this instance's")


def test_set_fmu_state_restores_the_instance_state(toys):
    a = toys()
    early = a.fmu.getFMUstate()  # taken in state instantiated
    a.init()
    a.run(3)
    a.fmu.setFMUstate(early)
    refused(a, a.fmu.doStep, 0.0, 0.01, match="state instantiated")
    a.init()
    a.step()
    a.fmu.freeFMUstate(early)


def test_serialize_round_trip_is_bit_identical(toys):
    a = toys()
    params = dict(tau=0.06, k=0.8, offset_file="offset.txt")
    a.init(**params)
    a.run(7)
    state = a.fmu.getFMUstate()
    data = a.fmu.serializeFMUstate(state)
    t = a.t
    reference = a.run(20)
    # into the same instance
    s2 = a.fmu.deSerializeFMUstate(data)
    a.fmu.setFMUstate(s2)
    a.t = t
    assert same(a.run(20), reference)
    # into a fresh instance with the same parameters, not initialised: the glue loads the data
    b = toys(name="b")
    b.set(**params)
    s3 = b.fmu.deSerializeFMUstate(data)
    b.fmu.setFMUstate(s3)
    b.t = t
    assert same(b.run(20), reference)
    # and into one that is initialised
    c = toys(name="c")
    c.init(**params)
    c.fmu.setFMUstate(c.fmu.deSerializeFMUstate(data))
    c.t = t
    assert same(c.run(20), reference)
    assert a.fmu.serializeFMUstate(s2) == data


def test_deserialize_refuses_bad_bytes(toys):
    a = toys()
    a.init()
    a.run(4)
    state = a.fmu.getFMUstate()
    data = a.fmu.serializeFMUstate(state)
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0x40
    rng = np.random.default_rng(1)
    cases = [
        (b"", "truncated"),
        (data[:10], "truncated"),
        (data[:-1], "checksum"),
        (data + b"x", "checksum"),
        (bytes(flipped), "checksum"),
        (rng.bytes(len(data)), "ipmsm-fmu state header"),
        (b"IPMSMFST" + rng.bytes(200), "checksum"),
    ]
    for bad, match in cases:
        refused(a, a.fmu.deSerializeFMUstate, bad, match=match)
    t = a.t
    before = a.run(5)
    a.fmu.setFMUstate(a.fmu.deSerializeFMUstate(data))  # the good bytes still work
    a.t = t
    assert same(a.run(5), before)


def test_deserialize_refuses_other_parameters(toys):
    a = toys()
    a.init(tau=0.1, n_sub=2)
    a.run(3)
    data = a.fmu.serializeFMUstate(a.fmu.getFMUstate())
    b = toys(name="b")
    b.set(tau=0.3, n_sub=2)
    refused(b, b.fmu.deSerializeFMUstate, data, match="tau = 0.1 there, 0.3 here")
    b.set(tau=0.1)
    b.fmu.setFMUstate(b.fmu.deSerializeFMUstate(data))


# --- logging and status queries ---

def test_logging_categories(toys):
    a = toys(logging_on=False)
    a.init(offset_file="offset.txt", tau=0.005)
    assert a.log.messages(fmi2OK) == []  # debug logging off: no info ...
    refused(a, a.set, u=1e9)
    assert a.log.errors()  # ... but errors always
    c = a.fmu.component
    # h > tau: the model warns; the step completes, so fmi2OK (strict importers stop on fmi2Warning)
    assert a.fmu.fmi2DoStep(c, a.t, 0.01, fmi2True) == fmi2OK
    a.t += 0.01
    assert a.log.messages(fmi2Warning) == []  # not logged: category off
    a.fmu.setDebugLogging(True, ["logStatusWarning"])
    assert a.fmu.fmi2DoStep(c, a.t, 0.01, fmi2True) == fmi2OK
    a.t += 0.01
    assert any("longer than tau" in m for m in a.log.messages(fmi2Warning, "logStatusWarning"))
    refused(a, a.fmu.setDebugLogging, True, ["logNonsense"], match="unknown log category")
    a.fmu.setDebugLogging(True, ["logAll"])
    a.log.clear()
    a.step()
    assert any("fmi2DoStep (state stepComplete)" in m for m in a.log.messages(fmi2OK, "logAll"))
    a.fmu.setDebugLogging(False, [])
    a.log.clear()
    a.step()
    assert a.log.records == []


def test_log_messages_are_printf_safe(toys):
    a = toys()
    a.set(offset_file="100%s.txt")
    a.fmu.enterInitializationMode()
    refused(a, a.fmu.exitInitializationMode, match="100%s.txt")
    assert "100%%s.txt" in a.log.raw


def test_status_queries_and_unsupported_functions(toys):
    a = toys()
    assert a.fmu.getTypesPlatform() == "default" and a.fmu.getVersion() == "2.0"
    a.init()
    a.run(3)
    assert a.fmu.getRealStatus(fmi2LastSuccessfulTime) == a.t
    assert a.fmu.getBooleanStatus(fmi2Terminated) is False
    refused(a, a.fmu.getStatus, fmi2DoStepStatus, status=fmi2Discard)
    refused(a, a.fmu.getStatus, fmi2PendingStatus, status=fmi2Discard)
    refused(a, a.fmu.getIntegerStatus, fmi2LastSuccessfulTime, status=fmi2Discard)
    refused(a, a.fmu.getStringStatus, fmi2PendingStatus, status=fmi2Discard)
    refused(a, a.fmu.getRealStatus, 42, match="unknown status kind 42")
    refused(a, a.fmu.cancelStep, match="no step to cancel")
    refused(a, a.fmu.setRealInputDerivatives, [a.vr("u")], [1], [1.0], match="canInterpolateInputs")
    refused(a, a.fmu.getRealOutputDerivatives, [a.vr("y")], [1], match="maxOutputDerivativeOrder")
    refused(a, a.fmu.getDirectionalDerivative, [a.vr("y")], [a.vr("u")], [1.0], match="providesDirectionalDerivative")
    a.fmu.terminate()
    assert a.fmu.getRealStatus(fmi2LastSuccessfulTime) == a.t
