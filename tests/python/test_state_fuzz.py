"""FMU states that cannot lie (issue 35, finding 6): a fuzz of every FMU's serialised state.

A serialised state's checksum is FNV-1a (docs: fmu_src/fmi/README.md), not a MAC: anyone can
recompute it. So each variant here has its checksum recomputed, and what is exercised is the FMU's
validation of the state's content. Variants of a real state (after steps at load, with and without
the thermal network): byte flips, truncations, extensions, and hostile values (0, -1, huge, tiny,
NaN, infinities, enum and count extremes) written over every variable and over the model's internal
fields. Each variant is either refused with fmi2Error (the instance unchanged and usable: it steps
from its own state afterwards) or accepted; an accepted state is installed and stepped twice (its
own inputs, then a new command), and the steps either succeed with every output finite and physical
(physical_violation) or are refused with fmi2Error, the instance usable after.

The default run draws DEFAULT_VARIANTS per configuration; @slow takes every variant (thousands per
FMU). tests/python/test_sanitizers.py runs this module under ASan and UBSan."""
from __future__ import annotations

import json
import math
import random
import struct
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import fmi2_raw as raw
from conftest import fmu_path, patient
from fmi2_raw import ERROR, OK, WARNING

#: (FMU, values at initialisation, inputs for the steps): a working point with current and speed
CONFIGS = {
    "controller": ("IpmsmController", {}, {"T_ref": 150.0, "w_m": 400.0, "i_d": -60.0, "i_q": 120.0}),
    "plant": ("IpmsmPlant", {}, {"u_d": -20.0, "u_q": 60.0, "w_m": 400.0}),
    "plant-thermal": ("IpmsmPlant", {"thermal_model": True}, {"u_d": -20.0, "u_q": 60.0, "w_m": 400.0}),
    "drive": ("IpmsmDrive", {}, {"T_ref": 150.0, "w_m": 400.0}),
    "drive-thermal": ("IpmsmDrive", {"thermal_model": True}, {"T_ref": 150.0, "w_m": 400.0}),
}
#: the inputs of a second step after an accepted state: a new command, solved from the state's memory
NEW_INPUTS = {"controller": {"T_ref": -120.0, "w_m": 900.0}, "plant": {"u_d": 40.0, "u_q": -30.0},
              "drive": {"T_ref": -120.0, "w_m": 900.0}}
STEP = 1e-4  # s: every FMU's default (IpmsmDrive: its sample_time)
STEPS_BEFORE = 20
DEFAULT_VARIANTS = 400
SEED = 35

HOSTILE_DOUBLES = [0.0, -0.0, -1.0, 0.5, 4.0, 1e6, -1e6, 1e300, -1e300, 5e-324, 2.0**53, 2.0**63, -(2.0**63),
                   math.nan, math.inf, -math.inf]
HOSTILE_INTS = [0, -1, 3, 4, 5, 100, 2**31 - 1, -(2**31)]

# What an output of a working drive can be (default motor: I_max 500 A, 285 N.m, psi about 0.1 Wb):
# twenty times that is no machine; the temperatures those the FMUs accept (machine.hpp).
AMPERES, NEWTON_METRES, WEBERS = 1e4, 1e4, 10.0
T_MIN_K, T_MAX_K = 173.15, 573.15


def physical_violation(name: str, value: float) -> str | None:
    if not math.isfinite(value):
        return f"{name} = {value} is not finite"
    bound = None
    if name in ("i_d", "i_q", "i_d_ref", "i_q_ref"):  # (not i_dc = P_dc / u_dc: u_dc is any input > 0)
        bound = AMPERES
    elif name in ("T_e", "T_shaft", "T_cmd", "T_max"):  # (not T_est: the torque of the measured currents,
        # inputs of which fmi2SetReal accepts any finite value, as a state does)
        bound = NEWTON_METRES
    elif name in ("psi_d", "psi_q", "psi_m_T"):
        bound = WEBERS
    elif name.startswith("theta_"):
        if not T_MIN_K <= value <= T_MAX_K:
            return f"{name} = {value} K is outside [{T_MIN_K}, {T_MAX_K}]"
    if bound is not None and abs(value) > bound:
        return f"{name} = {value} beyond {bound}"
    return None


# --- the serialised layout (fmu_src/fmi/fmu_state.hpp, format 4) ---

def fnv1a(data: bytes) -> int:
    h = 0xCBF29CE484222325
    for b in data:
        h = ((h ^ b) * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def sealed(body: bytes) -> bytes:
    """body with its checksum: what anyone can compute."""
    return body + struct.pack("<Q", fnv1a(body))


@dataclass
class Layout:
    time_at: int
    reals: list[int] = field(default_factory=list)  # offsets of the variables' doubles
    ints: list[int] = field(default_factory=list)   # offsets of their int32s
    at: list[int] = field(default_factory=list)     # each variable's value, by value reference
    block: tuple[int, int] = (0, 0)                 # the model's state fields: [start, end)


def layout(blob: bytes) -> Layout:
    p = 8 + 4
    for _ in range(2):  # model identifier, GUID
        (n,) = struct.unpack_from("<Q", blob, p)
        p += 8 + n
    p += 1 + 8  # phase, start time
    out = Layout(time_at=p)
    p += 8
    (n_vars,) = struct.unpack_from("<Q", blob, p)
    p += 8
    for _ in range(n_vars):
        kind = blob[p]
        p += 1
        out.at.append(p)
        if kind == 0:
            out.reals.append(p)
            p += 8
        elif kind == 1:
            out.ints.append(p)
            p += 4
        elif kind == 2:
            p += 1
        else:
            (n,) = struct.unpack_from("<Q", blob, p)
            p += 8 + n
    (n,) = struct.unpack_from("<Q", blob, p)
    out.block = (p + 8, p + 8 + n)
    assert out.block[1] + 8 == len(blob), "the state's layout is not format 4's"
    return out


def variants(blob: bytes, rng: random.Random) -> list[tuple[str, bytes]]:
    """Every hostile variant of blob, each sealed."""
    body, lay = blob[:-8], layout(blob)
    out: list[tuple[str, bytes]] = []

    def put(at: int, fmt: str, value, what: str):
        b = bytearray(body)
        struct.pack_into(fmt, b, at, value)
        out.append((what, sealed(bytes(b))))

    for at in lay.reals:
        for x in HOSTILE_DOUBLES:
            put(at, "<d", x, f"variable double at {at} = {x}")
    for at in lay.ints:
        for x in HOSTILE_INTS:
            put(at, "<i", x, f"variable int at {at} = {x}")
    start, end = lay.block
    for at in range(start, end - 7):
        for x in HOSTILE_DOUBLES:
            put(at, "<d", x, f"field double at {at} = {x}")
    for at in range(start, end - 3):
        for x in HOSTILE_INTS:
            put(at, "<i", x, f"field int at {at} = {x}")
    for at in range(start, end):
        for x in (0, 1, 2, 0xFF):
            put(at, "<B", x, f"field byte at {at} = {x}")
    for _ in range(len(body) * 2):
        b = bytearray(body)
        at = rng.randrange(len(b))
        b[at] ^= rng.randrange(1, 256)
        out.append((f"flip at {at}", sealed(bytes(b))))
    for n in sorted(rng.sample(range(len(body)), min(len(body), 300))):
        out.append((f"truncated to {n}", sealed(body[:n])))
    for n in (1, 7, 8, 64, 4096):
        out.append((f"extended by {n}", sealed(body + bytes(rng.randrange(256) for _ in range(n)))))
    return out


@dataclass
class Tally:
    refused: int = 0
    accepted: int = 0
    step_refused: int = 0
    failures: list[str] = field(default_factory=list)


def fuzz(config: str, tmp_path, sample: int | None) -> Tally:
    name, start, inputs = CONFIGS[config]
    fmu = raw.Unzipped(fmu_path(name), tmp_path / name)
    a = raw.Instance(fmu, f"fuzz-{config}")
    try:
        a.init(**start)
        a.set(**inputs)
        for _ in range(STEPS_BEFORE):
            assert a.step(STEP) == OK, a.log.text()
        good = a.get_state()
        good_time = a.t
        blob = a.serialize(good)
        assert a.deserialize_status(blob)[0] == OK, a.log.text()  # the real state is restored

        rng = random.Random(SEED)
        cases = variants(blob, rng)
        if sample is not None:
            cases = rng.sample(cases, min(sample, len(cases)))
        tally = Tally()
        outputs = a.names("output")
        for what, data in cases:
            a.log.clear()
            status, state = a.deserialize_status(data)
            if status != OK:
                tally.refused += 1
                if status != ERROR or state is not None or not a.log.text():
                    tally.failures.append(f"{what}: status {raw.STATUS.get(status)}, state {state}, log "
                                          f"{a.log.text()[:200]!r}")
                # the instance is untouched: it steps on from its own state
                if a.step(STEP, t=good_time) != OK:
                    tally.failures.append(f"{what}: refused, then the instance did not step\n{a.log.text()[-500:]}")
                assert a.set_state(good) == OK
                continue
            tally.accepted += 1
            assert a.set_state(state) == OK, a.log.text()
            (t,) = struct.unpack_from("<d", data, layout(data).time_at)
            step = a.step(STEP, t=t)
            if step in (OK, WARNING):
                for x, v in NEW_INPUTS[config.split("-")[0]].items():
                    a.set_status(x, v)
                step = a.step(STEP, t=t + STEP)
            if step in (OK, WARNING):
                for n in outputs:
                    s, v = a.get_status(n)
                    why = physical_violation(n, float(v)) if s == OK else f"fmi2Get {n}: {raw.STATUS.get(s)}"
                    if why:
                        tally.failures.append(f"{what}: accepted, after two steps {why}")
                        break
            else:
                tally.step_refused += 1
            a.free_state(state)
            assert a.set_state(good) == OK
            if step not in (OK, WARNING) and a.step(STEP, t=good_time) != OK:
                tally.failures.append(f"{what}: the step after it was refused, then the instance did not step")
            assert a.set_state(good) == OK
        print(f"\n[state fuzz] {config}: {len(cases)} variants of a {len(blob)}-byte state: {tally.refused} refused, "
              f"{tally.accepted} accepted ({tally.step_refused} of them refused at the next step), "
              f"{len(tally.failures)} wrong")
        return tally
    finally:
        a.free()


@pytest.mark.parametrize("config", list(CONFIGS))
def test_every_state_variant_is_refused_or_runs_physically(config, tmp_path):
    tally = fuzz(config, tmp_path, DEFAULT_VARIANTS)
    assert not tally.failures, "\n".join(tally.failures[:20])
    assert tally.refused > 0 and tally.accepted > 0  # the fuzz reaches both outcomes


@pytest.mark.slow
@pytest.mark.parametrize("config", list(CONFIGS))
def test_every_state_variant_is_refused_or_runs_physically_all(config, tmp_path):
    tally = fuzz(config, tmp_path, None)
    assert not tally.failures, "\n".join(tally.failures[:20])
    assert tally.refused + tally.accepted > 2000


# --- the cases of the finding, named ---

def _state(name: str, start: dict, inputs: dict, tmp_path):
    fmu = raw.Unzipped(fmu_path(name), tmp_path / name)
    a = raw.Instance(fmu, name)
    a.init(**start)
    a.set(**inputs)
    for _ in range(STEPS_BEFORE):
        assert a.step(STEP) == OK, a.log.text()
    return a, a.serialize(a.get_state())


_METHOD_CHILD = r"""
import json, struct, sys, tempfile
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from test_state_fuzz import STEP, _state, layout, sealed
method = int(sys.argv[2])
a, blob = _state("IpmsmDrive", {}, {"T_ref": 150.0, "w_m": 400.0}, Path(tempfile.mkdtemp()))
good = a.get_state()
lay = layout(blob)
out = {"variable": None, "fields": []}
body = bytearray(blob[:-8])
# the drive's variable `method` ...
struct.pack_into("<i", body, lay.at[a.fmu.vars["method"].valueReference], method)
status, state = a.deserialize_status(sealed(bytes(body)))
out["variable"] = [status, a.log.text()[-300:]]
# ... and every int32 1 of the model's fields (format 3 held the controller's method there again)
for at in range(lay.block[0], lay.block[1] - 3):
    if struct.unpack_from("<i", blob, at)[0] != 1:
        continue
    body = bytearray(blob[:-8])
    struct.pack_into("<i", body, at, method)
    status, state = a.deserialize_status(sealed(bytes(body)))
    stepped = None
    if status == 0:
        a.set_state(state)
        a.set(T_ref=-120.0, w_m=900.0)  # a new command: the controller solves it by its method
        (t,) = struct.unpack_from("<d", body, lay.time_at)
        stepped = a.step(STEP, t=t)
        a.set_state(good)
    out["fields"].append([at, status, stepped])
print(json.dumps(out))
"""


@pytest.mark.parametrize("method", [0, 4, -1, 2**31 - 1])
def test_a_drive_state_with_an_invalid_controller_method_never_crashes(method):
    """A drive state whose embedded controller `method` was 0, 4 or -1 passed and the next
    fmi2DoStep crashed (SIGSEGV): the drive held its controller's parameters a second time,
    unchecked. Now the drive's variables hold them once: the variable is refused naming it, and
    no int32 of the model's fields set to the method crashes a step (in a child process)."""
    r = subprocess.run([sys.executable, "-c", _METHOD_CHILD, str(Path(__file__).parent), str(method)],
                       capture_output=True, text=True, timeout=patient(300))
    assert r.returncode == 0, f"the child died ({r.returncode}): {r.stderr[-2000:]}"
    out = json.loads(r.stdout.splitlines()[-1])
    status, log = out["variable"]
    assert status == ERROR and "method" in log and "out of range" in log, log
    assert out["fields"], "no int32 1 among the fields"
    for at, status, stepped in out["fields"]:
        assert status == ERROR or stepped in (OK, WARNING, ERROR), (at, status, stepped)


@pytest.mark.parametrize("name", ["IpmsmPlant", "IpmsmDrive"])
def test_node_temperatures_of_a_million_kelvin_are_refused(name, tmp_path):
    inputs = {"u_d": -20.0, "u_q": 60.0, "w_m": 400.0} if name == "IpmsmPlant" else {"T_ref": 150.0, "w_m": 400.0}
    a, blob = _state(name, {"thermal_model": True, "T_winding": 350.125, "T_magnet": 330.125}, inputs, tmp_path)
    try:
        body = blob[:-8]
        hot = body
        for t in {a.get("theta_winding"), a.get("theta_magnet"), a.get("theta_stator_yoke"),
                  a.get("theta_stator_tooth")}:
            hot = hot.replace(struct.pack("<d", t), struct.pack("<d", 1e6))
        assert hot != body
        status, state = a.deserialize_status(sealed(hot))
        assert status == ERROR and state is None, a.log.text()
        assert "temperature" in a.log.text() or "theta" in a.log.text(), a.log.text()
        assert a.step(STEP) == OK
    finally:
        a.free()


def test_the_drive_step_count_is_a_whole_number(tmp_path):
    a, blob = _state("IpmsmDrive", {}, {"T_ref": 150.0, "w_m": 400.0}, tmp_path)
    try:
        lay = layout(blob)
        (k,) = struct.unpack_from("<d", blob, lay.block[0])
        assert k == STEPS_BEFORE  # the count is the block's first field
        for bad in (-1.0, 20.5, 1e300, 2.0**63):
            body = bytearray(blob[:-8])
            struct.pack_into("<d", body, lay.block[0], bad)
            status, state = a.deserialize_status(sealed(bytes(body)))
            assert status == ERROR and state is None, (bad, a.log.text())
            assert "step count" in a.log.text(), a.log.text()
        assert a.step(STEP) == OK
    finally:
        a.free()
