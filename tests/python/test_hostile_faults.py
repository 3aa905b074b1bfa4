"""The hostile corpus (test_hostile.py) extended to the inverter's safe states (issue 33): every
Real input's hostile values while the plant freewheels or short-circuits, and while IpmsmDrive is in
a fault; inverter_state and safe_state outside 0-2 refused with fmi2Error, changing nothing (the
instance then steps exactly as an untouched twin); a serialised state with an inverter_state out of
range refused like a set. "Fails cleanly" as in test_hostile.py."""
from __future__ import annotations

import math

import pytest
from test_hostile import HOSTILE_VALUES, twins
from test_hostile_bounds import _rechecked

from fmi2_raw import ERROR, OK, WARNING

NORMAL = {
    "IpmsmPlant": dict(u_d=-20.0, u_q=60.0, w_m=900.0, T_magnet=330.0, T_winding=350.0, u_dc=355.0),
    "IpmsmDrive": dict(T_ref=100.0, w_m=900.0, u_dc=355.0, T_magnet=330.0, T_winding=350.0),
}
STATES = {"IpmsmPlant": [("inverter_state", 1), ("inverter_state", 2)], "IpmsmDrive": [("fault", True)]}
BAD_INTEGERS = [-1, 3, 7, 2**31 - 1, -2**31]


def step(inst, n=1):
    h = 1e-3 if "fault" in inst.fmu.vars else 1e-4  # IpmsmDrive: whole multiples of its sample time
    return [inst.step(h) for _ in range(n)]


@pytest.mark.parametrize("name,state", [(n, s) for n in STATES for s in STATES[n]], ids=str)
@pytest.mark.parametrize("value", HOSTILE_VALUES, ids=repr)
def test_hostile_inputs_in_a_safe_state_fail_cleanly(make, name, state, value):
    normal = {**NORMAL[name], state[0]: state[1]}
    for inp in NORMAL[name]:
        a, ref = twins(make, name)
        for inst in (a, ref):
            inst.set(**normal)
            assert step(inst, 2) == [OK, OK], inst.log.text()
        status = a.set_status(inp, value)
        if status == ERROR:
            assert a.outputs() == ref.outputs()
        else:
            before = a.outputs()
            s = step(a)[0]
            assert s in (OK, WARNING, ERROR), (inp, value, s)
            if s == ERROR:
                assert repr(a.outputs()) == repr(before) and "was undone" in a.log.text()
            else:
                assert all(math.isfinite(x) for x in a.outputs()), (inp, value, a.outputs())
        a.set(**normal)
        assert step(a)[0] in (OK, WARNING) and all(math.isfinite(x) for x in a.outputs()), a.log.text()


@pytest.mark.parametrize("name,variable", [("IpmsmPlant", "inverter_state"), ("IpmsmDrive", "safe_state")])
@pytest.mark.parametrize("bad", BAD_INTEGERS)
def test_states_outside_0_to_2_are_refused_and_change_nothing(make, name, variable, bad):
    a, ref = make(name), make(name)
    for inst in (a, ref):
        assert inst.setup() == OK and inst.enter() == OK
    assert a.set_status(variable, bad) == ERROR and "out of range" in a.log.text(), a.log.text()
    for inst in (a, ref):
        assert inst.exit() == OK
        inst.set(**NORMAL[name])
    if variable == "inverter_state":
        assert a.set_status(variable, bad) == ERROR  # an input: refused in Step Mode too
    for _ in range(3):
        assert step(a) == [OK] and step(ref) == [OK]
        assert a.outputs() == ref.outputs()


def test_a_deserialised_inverter_state_out_of_range_is_refused(make):
    import struct
    a = make("IpmsmPlant")
    a.init(w_m=900.0)
    a.set(inverter_state=2)
    a.step()
    blob = a.serialize(a.get_state())
    # the Integer inputs are stored as int32 after their type index 1: patch inverter_state's 2 to 5
    marker = bytes([1]) + struct.pack("<i", 2)
    assert blob.count(marker) >= 1
    status, state = a.deserialize_status(_rechecked(blob.replace(marker, bytes([1]) + struct.pack("<i", 5))))
    assert status == ERROR and state is None and "inverter_state" in a.log.text(), a.log.text()
    assert a.step() == OK
