"""The flux map as FMI 3.0 array parameters (docs/spec/INTERFACE.md, "The flux map as arrays"):
the structural parameters n_i_d, n_i_q set in Configuration Mode, then i_d_axis, i_q_axis,
psi_d_map, psi_q_map. A map given so gives the same outputs as the same map given as a file, bit
for bit (the default map and the Prius FEM map, in all three FMUs); lengths that disagree with the
structural parameters, a map that folds in the operating region, both a file and arrays, lengths
beyond the map limits: each refused with fmi3Error naming why, the instance usable after it; the
arrays travel in the FMU state."""
from __future__ import annotations

import ctypes as C

import fmi3_raw as f3
import numpy as np
import pytest
from map_corpus import BY_NAME
from test_controller_corpus import K_PSI_T, K_U, T_MAGNET_REF
from test_hostile_maps import falling_map

from scenarios.maps.flux_map import DEFAULT_MAP, FluxMap, read_flux_map

NAMES = ("IpmsmController", "IpmsmPlant", "IpmsmDrive")
ARRAYS = ("i_d_axis", "i_q_axis", "psi_d_map", "psi_q_map")
#: the map limits of the contract (fmu_src/machine/flux_map.hpp: kMaxGridAxis values on an axis)
MAX_AXIS = 512
#: steps run per configuration: enough for the currents to settle into the commanded ones
STEPS = 200


@pytest.fixture
def instances3(instances3):
    """conftest's, logging every category but the call trace (the tests read the warnings)."""
    return lambda name, instance_name="instance": instances3(name, instance_name, logging_on=True)


def vr(inst: f3.Instance3, *names: str) -> list[int]:
    return [inst.fmu.vars[n].valueReference for n in names]


def set_lengths(inst: f3.Instance3, n_i_d: int, n_i_q: int) -> int:
    """n_i_d, n_i_q in Configuration Mode; the status of their Set."""
    assert inst.enter_configuration() == f3.OK, inst.log.text()
    status = inst.set_values("UInt64", ("n_i_d", "n_i_q"), [n_i_d, n_i_q])
    assert inst.exit_configuration() == f3.OK, inst.log.text()
    return status


def map_values(fmap: FluxMap) -> list[float]:
    """The four arrays one after the other, as one fmi3SetFloat64 takes them (row-major: [j][k] at
    j n_i_q + k)."""
    return [*fmap.i_d, *fmap.i_q, *np.ravel(fmap.psi_d), *np.ravel(fmap.psi_q)]


def give_map(inst: f3.Instance3, fmap: FluxMap) -> int:
    """The map as arrays (lengths, then one Set of the four arrays); the status of that Set."""
    assert set_lengths(inst, len(fmap.i_d), len(fmap.i_q)) == f3.OK, inst.log.text()
    return inst.set_values("Float64", ARRAYS, map_values(fmap))


def parameters(name: str, corpus_name: str) -> dict:
    """The drive's data of a corpus map, those of the FMU `name` (the plant has no k_u)."""
    m = BY_NAME[corpus_name]
    p = dict(pole_pairs=m.pole_pairs, R_s=m.R_s, I_max=m.I_max, k_psi_T=K_PSI_T, T_magnet_ref=T_MAGNET_REF)
    if name != "IpmsmPlant":
        p.update(k_u=K_U, w_m_max=m.w_m_max, u_dc=m.u_dc)
    else:
        p.update(u_dc=m.u_dc)
    return p


def drive_inputs(name: str, corpus_name: str, k: int) -> dict:
    """Inputs of step k: a torque ramp at a speed in field weakening for the controller and the
    drive, a voltage ramp at speed for the plant."""
    m = BY_NAME[corpus_name]
    if name == "IpmsmPlant":
        return dict(w_m=0.3 * m.w_m_max, u_d=-0.05 * m.u_dc * k / STEPS, u_q=0.1 * m.u_dc * k / STEPS)
    T = 2.0 * m.pole_pairs * m.I_max * 0.05 * k / STEPS  # up to some tenths of the peak torque
    return dict(w_m=0.6 * m.w_m_max, T_ref=T)


def trace(inst: f3.Instance3, name: str, corpus_name: str) -> list[tuple]:
    rows = []
    for k in range(STEPS):
        inst.set(**drive_inputs(name, corpus_name, k))
        assert inst.step(1e-4) == f3.OK, inst.log.text()
        rows.append(inst.outputs())
    return rows


def warnings(inst: f3.Instance3) -> list[str]:
    """The warnings logged, the map's name taken out (a file's path, or the arrays')."""
    return [m for s, _, m in ((s, c, m.decode()) for s, c, m in inst.log.records) if s == f3.WARNING]


@pytest.mark.parametrize("corpus_name", ["default", "prius"])
@pytest.mark.parametrize("name", NAMES)
def test_a_map_as_arrays_gives_the_outputs_of_the_same_map_as_a_file(instances3, name, corpus_name, tmp_path):
    m = BY_NAME[corpus_name]
    path = m.path(tmp_path)
    fmap = read_flux_map(path)
    params = parameters(name, corpus_name)
    from_file = instances3(name, "file")
    from_file.init(flux_map=str(path), **params)
    as_arrays = instances3(name, "arrays")
    assert give_map(as_arrays, fmap) == f3.OK, as_arrays.log.text()
    as_arrays.init(flux_map="", **params)
    # the arrays read back as given
    got = as_arrays.get_values("Float64", ARRAYS, len(map_values(fmap)))
    assert list(got) == map_values(fmap)
    assert as_arrays.get_values("UInt64", ("n_i_d", "n_i_q"), 2) == [len(fmap.i_d), len(fmap.i_q)]
    a, b = trace(from_file, name, corpus_name), trace(as_arrays, name, corpus_name)
    assert a == b, f"{name} on {corpus_name}: the arrays' outputs differ from the file's"
    # the test can fail: the run is not at rest (the outputs change along it)
    assert a[0] != a[-1]
    # the same warnings (the Prius map folds outside the operating region), naming the arrays
    wa = [w.replace(str(path), "MAP") for w in warnings(from_file)]
    wb = [w.replace(f3_arrays_name(), "MAP") for w in warnings(as_arrays)]
    metadata_free = [w for w in wa if "metadata" not in w]  # the file's metadata lines: not in arrays
    assert [w for w in wb if "metadata" not in w] == metadata_free
    if corpus_name == "prius":
        assert any("MAP" in w and "fold" in w for w in wb), wb


def f3_arrays_name() -> str:
    """What the FMUs' messages call a map given as arrays (fmu_src/parts/motor_map.hpp)."""
    return "the flux-map arrays (i_d_axis, i_q_axis, psi_d_map, psi_q_map)"


def refused_with(inst: f3.Instance3, status: int, *words: str) -> str:
    """The last error logged, after a call that returned `status`: fmi3Error with every word."""
    assert status == f3.ERROR, inst.log.text()
    errors = [m.decode() for s, _, m in inst.log.records if s == f3.ERROR]
    assert errors, "refused without a log line"
    for w in words:
        assert w in errors[-1], (w, errors[-1])
    return errors[-1]


@pytest.mark.parametrize("name", NAMES)
def test_lengths_that_disagree_with_the_structural_parameters_are_refused(instances3, name):
    fmap = read_flux_map(DEFAULT_MAP)
    inst = instances3(name)
    assert set_lengths(inst, len(fmap.i_d), len(fmap.i_q)) == f3.OK
    values = map_values(fmap)
    refs = ARRAYS
    for given in (values[:-1], values + [0.0], values[:4]):
        status = inst.set_values("Float64", refs, given)
        refused_with(inst, status, f"nValues = {len(given)}", f"name {len(values)} values",
                     f"psi_d_map: n_i_d x n_i_q = {len(fmap.i_d)} x {len(fmap.i_q)}")
    # one array given the other's length
    status = inst.set_values("Float64", ("i_d_axis",), list(fmap.i_q))
    if len(fmap.i_q) != len(fmap.i_d):
        refused_with(inst, status, "i_d_axis: n_i_d", f"= {len(fmap.i_d)} values")
    # nothing was changed: the arrays are zeros of the lengths set, and the instance takes the map
    assert inst.enter() == f3.OK
    assert set(inst.get_values("Float64", ("psi_d_map",), len(fmap.i_d) * len(fmap.i_q))) == {0.0}
    assert inst.set_values("Float64", refs, values) == f3.OK
    assert inst.exit() == f3.OK, inst.log.text()
    assert inst.step(1e-4) == f3.OK


@pytest.mark.parametrize("name", NAMES)
def test_a_map_that_folds_in_the_operating_region_is_refused_as_the_file_is(instances3, name, tmp_path):
    path = tmp_path / "fold.csv"
    falling_map(path)
    fmap = read_flux_map(path)
    from_file = instances3(name, "file")
    from_file.set(flux_map=str(path))
    assert from_file.enter() == f3.OK
    why_file = refused_with(from_file, from_file.exit(), str(path), "operating region")
    as_arrays = instances3(name, "arrays")
    assert give_map(as_arrays, fmap) == f3.OK
    assert as_arrays.enter() == f3.OK
    why_arrays = refused_with(as_arrays, as_arrays.exit(), f3_arrays_name(), "operating region", "i_q = 100 A")
    # the same reason, but for the map's name
    assert why_arrays.replace(f3_arrays_name(), "MAP") == why_file.replace(str(path), "MAP")
    # usable after it: the default map's arrays instead, then initialised and stepped
    assert as_arrays.set_values("Float64", ARRAYS, map_values(read_flux_map(DEFAULT_MAP))) == f3.OK
    assert as_arrays.exit() == f3.OK, as_arrays.log.text()
    assert as_arrays.step(1e-4) == f3.OK


def test_a_file_and_arrays_together_are_refused(instances3, tmp_path):
    fmap = read_flux_map(DEFAULT_MAP)
    inst = instances3("IpmsmController")
    assert give_map(inst, fmap) == f3.OK
    inst.set(flux_map=str(DEFAULT_MAP))
    assert inst.enter() == f3.OK
    refused_with(inst, inst.exit(), "both give a flux map", "n_i_d = n_i_q = 1")


@pytest.mark.parametrize("name", NAMES)
def test_lengths_beyond_the_map_limits_and_outside_configuration_mode_are_refused(instances3, name):
    inst = instances3(name)
    refs = ("n_i_d", "n_i_q")
    # outside Configuration Mode
    refused_with(inst, inst.set_values("UInt64", refs, [8, 8]), "ConfigurationMode")
    assert inst.enter_configuration() == f3.OK
    for n in (MAX_AXIS + 1, 2**32, 2**64 - 1):
        refused_with(inst, inst.set_values("UInt64", refs, [4, n]), "n_i_q", "out of range",
                     f"[0, {MAX_AXIS}]")
    # logging can be changed there, and fmi3Reset leaves it (back to Instantiated, no lengths)
    assert inst.call("fmi3SetDebugLogging", inst.c, True, 0, None) == f3.OK
    assert inst.reset() == f3.OK and inst.enter_configuration() == f3.OK
    # other parameters cannot be set in Configuration Mode, nor can the mode be left twice
    refused_with(inst, inst.set_values("Float64", ("R_s",), [0.02]), "not a structural parameter")
    # the largest grid is taken (its arrays are then MAX_AXIS^2 zeros) and refused at initialisation
    assert inst.set_values("UInt64", refs, [MAX_AXIS, MAX_AXIS]) == f3.OK
    assert inst.exit_configuration() == f3.OK
    assert inst.exit_configuration() == f3.ERROR
    assert inst.enter() == f3.OK
    assert len(inst.get_values("Float64", ("psi_q_map",), MAX_AXIS**2)) == MAX_AXIS**2
    refused_with(inst, inst.exit(), f3_arrays_name())
    # back to no arrays: the default map in resources/
    assert inst.reset() == f3.OK
    inst.init()
    assert inst.step(1e-4) == f3.OK


@pytest.mark.parametrize("name", NAMES)
def test_null_arrays_and_counts_that_do_not_add_up_are_refused(instances3, name):
    inst = instances3(name)
    assert set_lengths(inst, 4, 5) == f3.OK
    assert inst.enter() == f3.OK
    refs = (C.c_uint32 * 2)(*vr(inst, "i_d_axis", "i_q_axis"))
    values = (C.c_double * 9)(*range(9))
    call = inst.call
    assert call("fmi3SetFloat64", inst.c, refs, 2, None, 9) == f3.ERROR
    assert call("fmi3SetFloat64", inst.c, None, 2, values, 9) == f3.ERROR
    assert call("fmi3GetFloat64", inst.c, refs, 2, None, 9) == f3.ERROR
    for n in (0, 1, 2, 8, 10, 2**62):
        assert call("fmi3SetFloat64", inst.c, refs, 2, values, n) == f3.ERROR
        assert call("fmi3GetFloat64", inst.c, refs, 2, values, n) == f3.ERROR
    refused_with(inst, f3.ERROR, "nValues = 4611686018427387904", "name 9 values", "i_d_axis: n_i_d = 4 = 4 values")
    # a non-finite element, refused naming it; nothing set
    bad = (C.c_double * 9)(*range(9))
    bad[6] = float("nan")
    assert call("fmi3SetFloat64", inst.c, refs, 2, bad, 9) == f3.ERROR
    refused_with(inst, f3.ERROR, "i_q_axis[2]", "not a finite number")
    assert call("fmi3SetFloat64", inst.c, refs, 2, values, 9) == f3.OK
    assert inst.get_values("Float64", ("i_d_axis", "i_q_axis"), 9) == list(range(9))


@pytest.mark.parametrize("name", NAMES)
def test_the_arrays_travel_in_the_fmu_state(instances3, name, tmp_path):
    m = BY_NAME["prius"]
    path = m.path(tmp_path)
    fmap = read_flux_map(path)
    params = parameters(name, "prius")
    a = instances3(name, "a")
    assert give_map(a, fmap) == f3.OK
    a.init(**params)
    for k in range(20):
        a.set(**drive_inputs(name, "prius", k))
        assert a.step(1e-4) == f3.OK
    data, t_saved = a.serialize(a.get_state()), a.t
    after = trace(a, name, "prius")
    # an instance given the same map takes the state and continues as `a` did
    b = instances3(name, "b")
    assert give_map(b, fmap) == f3.OK
    b.set(**params)
    b.restore(data, t_saved)
    assert trace(b, name, "prius") == after
    # an instance given another map refuses it (a fixed parameter differs), naming the array
    c = instances3(name, "c")
    other = read_flux_map(path)
    other.psi_d[0, 0] += 1e-3
    assert give_map(c, other) == f3.OK
    c.set(**params)
    status, _ = c.deserialize_status(data)
    refused_with(c, status, "psi_d_map differs")


@pytest.mark.parametrize("name", NAMES)
def test_an_fmi3_state_on_arrays_is_refused_by_the_fmi2_fmu(name, instances3, fmu_instances):
    """FMI 2.0 has no arrays: a state saved on a map given as arrays would continue on another map
    there (its own flux_map), so it is refused naming them; one saved without arrays continues."""
    params = parameters(name, "default")
    for arrays in (False, True):
        three = instances3(name, f"three{arrays}")
        if arrays:
            assert give_map(three, read_flux_map(DEFAULT_MAP)) == f3.OK
        three.init(**params)
        for k in range(10):
            three.set(**drive_inputs(name, "default", k))
            assert three.step(1e-4) == f3.OK
        data = three.serialize(three.get_state())
        two = fmu_instances(name, f"two{arrays}")
        two.set(**params)
        status, _ = two.deserialize_status(data)
        if arrays:
            assert status == f3.ERROR
            for words in ("other fixed parameters", f"n_i_d = {len(read_flux_map(DEFAULT_MAP).i_d)} there, 1 here",
                          "psi_d_map differs"):
                assert words in two.log.text(), two.log.text()
        else:
            assert status == f3.OK, two.log.text()
