"""Both FMUs are what the FMI 2.0 standard promises (issue 5), checked by tools that catch
different things:

- VDMCheck2 (INTO-CPS; a VDM-SL model of the standard's XML rules, Maven Central, installed by
  scripts/setup.sh into build-tools/): zero problems. fmpy's own validator runs in
  test_controller_fmu.py::test_validates_with_fmpy and test_plant_fmu.py::test_fmpy_validate.
- The binary (readelf/nm): exactly the 34 FMI 2.0 common and co-simulation functions exported,
  no shared library beyond libc, libm, libgcc_s, the glibc symbol versions it needs (reported;
  at most RHEL 8's 2.28), every symbol resolvable at load (LD_BIND_NOW), no executable stack.
  ToyLag, the glue's test FMU, is built the same way and checked too.
- The Windows binary (binaries/win64, issue 17; x86_64-w64-mingw32-objdump): an x86-64 DLL
  exporting exactly the same 34 functions and importing only Windows' own DLLs (KERNEL32 and the
  C runtime: msvcrt, or the UCRT's ucrtbase/api-ms-win-crt-*), so it loads on a bare Windows. So
  VDMCheck2 and fmpy's validator above check the two-platform FMUs. tests/python/test_win64.py
  runs the DLLs under wine. Skipped with IPMSM_WIN64=OFF (the set-up's switch) and on the
  sanitizer build (Linux only).
- The model description against the binary: every variable's value reference, type, causality,
  variability and start value as the code has them (the XML is generated from the same C++
  table; this checks the XML that ships against the code that ships), outputs readable in
  Initialization Mode with their values after initialisation (they are InitialUnknowns), and the
  capabilities it declares.
- The model description against the contract (docs/spec/INTERFACE.md): names, causality,
  type, unit and display units.
- documentation/index.html inside the FMU: explains the method and every variable.
"""
from __future__ import annotations

import html
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description

import fmi2_raw as raw
from conftest import ROOT, WIN64_BUILT, fmu_path, patient

REAL_FMUS = ["IpmsmController", "IpmsmPlant", "IpmsmDrive"]
ALL_FMUS = REAL_FMUS + ["ToyLag"]  # ToyLag: the glue's test FMU, built by the same add_fmu()
GLIBC_BASELINE = (2, 28)  # RHEL 8 (Ubuntu 20.04 has 2.31)
ALLOWED_LIBRARIES = {"libc.so.6", "libm.so.6", "libgcc_s.so.1", "ld-linux-x86-64.so.2"}
WINDOWS_SYSTEM_DLLS = re.compile(r"(kernel32|msvcrt|ucrtbase|api-ms-win-crt-[a-z0-9-]+)\.dll", re.IGNORECASE)
VDMCHECK2 = Path(os.environ.get("IPMSM_VDMCHECK2_JAR", ROOT / "build-tools" / "vdmcheck2-1.1.3" / "vdmcheck2.jar"))


def _library(name, unzipped) -> Path:
    return unzipped(name).library


def _tool(name):
    path = shutil.which(name)
    assert path, f"{name} (binutils) is not installed: scripts/setup.sh installs build-essential"
    return path


def _sanitizer_build(lib: Path) -> bool:
    dyn = subprocess.run([_tool("readelf"), "-d", str(lib)], check=True, capture_output=True, text=True).stdout
    return "libasan" in dyn or "libubsan" in dyn


# --- VDMCheck2 ---

@pytest.mark.parametrize("name", REAL_FMUS)
def test_vdmcheck2_finds_no_problem(name):
    java = shutil.which("java")
    assert java and VDMCHECK2.is_file(), (
        f"VDMCheck2 is not installed ({VDMCHECK2}): scripts/setup.sh installs it (scripts/install_vdmcheck2.sh)")
    r = subprocess.run([java, "-jar", str(VDMCHECK2), str(fmu_path(name))], capture_output=True, text=True,
                       timeout=patient(300))
    report = r.stdout + r.stderr
    print(f"\n[VDMCheck2 {name}] {report.strip()}")
    assert r.returncode == 0 and "No errors found." in report, report


def test_vdmcheck2_does_find_problems(tmp_path):
    """The checker is really checking: a model description with a calculated output that has a
    start value and a stop time before the start time is refused."""
    java = shutil.which("java")
    assert java and VDMCHECK2.is_file(), f"VDMCheck2 is not installed ({VDMCHECK2})"
    with zipfile.ZipFile(fmu_path("IpmsmPlant")) as z:
        xml = z.read("modelDescription.xml").decode()
    bad = xml.replace('stopTime="0.1"', 'stopTime="-1"', 1)
    bad = re.sub(r'(initial="calculated">\s*<Real unit="A")', r'\1 start="3"', bad, count=1)
    assert bad != xml
    (tmp_path / "modelDescription.xml").write_text(bad)
    r = subprocess.run([java, "-jar", str(VDMCHECK2), str(tmp_path / "modelDescription.xml")],
                       capture_output=True, text=True, timeout=patient(300))
    assert r.returncode != 0 and "Errors found." in r.stdout, r.stdout + r.stderr
    assert "validStartStopTime" in r.stdout and "validVariableAttributes" in r.stdout, r.stdout


# --- the binary ---

@pytest.mark.parametrize("name", ALL_FMUS)
def test_exports_exactly_the_fmi2_functions(name, unzipped):
    lib = _library(name, unzipped)
    nm = subprocess.run([_tool("nm"), "-D", "--defined-only", str(lib)], check=True, capture_output=True,
                        text=True).stdout
    exported = {line.split()[-1] for line in nm.splitlines() if line.strip()}
    assert exported == raw.FMI2_FUNCTIONS, (exported - raw.FMI2_FUNCTIONS, raw.FMI2_FUNCTIONS - exported)


@pytest.mark.parametrize("name", ALL_FMUS)
def test_needs_only_the_c_runtime(name, unzipped):
    lib = _library(name, unzipped)
    if _sanitizer_build(lib):
        pytest.skip("a sanitizer build (IPMSM_SANITIZE) links the sanitizer runtimes and libstdc++ dynamically")
    dyn = subprocess.run([_tool("readelf"), "-d", str(lib)], check=True, capture_output=True, text=True).stdout
    needed = set(re.findall(r"\(NEEDED\)\s+Shared library: \[([^\]]+)\]", dyn))
    assert needed and needed <= ALLOWED_LIBRARIES, needed
    assert "TEXTREL" not in dyn
    headers = subprocess.run([_tool("readelf"), "-lW", str(lib)], check=True, capture_output=True, text=True).stdout
    stack = [line for line in headers.splitlines() if "GNU_STACK" in line]
    assert stack and "RWE" not in stack[0], "executable stack"


def _versions(lib: Path) -> dict[str, set[str]]:
    """Version references of a shared library: {"libc.so.6": {"GLIBC_2.2.5", ...}, ...}."""
    out = subprocess.run([_tool("readelf"), "-V", "-W", str(lib)], check=True, capture_output=True, text=True).stdout
    refs, current = {}, None
    section = out.split(".gnu.version_r", 1)[1] if ".gnu.version_r" in out else ""
    for line in section.splitlines():
        m = re.search(r"File: (\S+)", line)
        if m:
            current = m.group(1)
            refs[current] = set()
        m = re.search(r"Name: (\S+)", line)
        if m and current:
            refs[current].add(m.group(1))
    return refs


def _version_tuple(v: str) -> tuple[int, ...]:
    return tuple(int(x) for x in v.split("_", 1)[1].split("."))


@pytest.mark.parametrize("name", ALL_FMUS)
def test_glibc_baseline(name, unzipped):
    lib = _library(name, unzipped)
    if _sanitizer_build(lib):
        pytest.skip("a sanitizer build (IPMSM_SANITIZE) needs the build machine's glibc")
    refs = _versions(lib)
    glibc = {v for vs in refs.values() for v in vs if v.startswith("GLIBC_") and v != "GLIBC_PRIVATE"}
    gcc = {v for vs in refs.values() for v in vs if v.startswith("GCC_")}
    assert glibc, refs
    highest = max(glibc, key=_version_tuple)
    highest_gcc = max(gcc, key=_version_tuple) if gcc else "none"
    print(f"\n[{name}] needs glibc >= {highest[6:]} (RHEL 8: 2.28, Ubuntu 20.04: 2.31), libgcc_s >= {highest_gcc}; "
          f"{', '.join(f'{k}: {len(v)} versions' for k, v in sorted(refs.items()))}")
    assert not any(v.startswith("GLIBCXX_") or v.startswith("CXXABI_") for vs in refs.values() for v in vs), \
        "libstdc++ must be linked statically"
    assert _version_tuple(highest) <= GLIBC_BASELINE, f"{highest} > GLIBC_{'.'.join(map(str, GLIBC_BASELINE))}"
    # GCC_4.2.0: libgcc_s of GCC 4.2 (2007) and later; RHEL 8 has GCC 8's
    assert _version_tuple(highest_gcc) <= (4, 2, 0) if gcc else True


@pytest.mark.parametrize("name", ALL_FMUS)
def test_every_symbol_resolves_at_load(name, unzipped):
    """RTLD_NOW with LD_BIND_NOW: the pinned symbol versions (fmu_src/fmi/glibc_compat.cpp) exist."""
    lib = _library(name, unzipped)
    code = ("import ctypes, sys; h = ctypes.CDLL(sys.argv[1], mode=ctypes.RTLD_LOCAL | 2); "
            "print(h.fmi2GetVersion and ctypes.cast(h.fmi2GetVersion, ctypes.c_void_p).value is not None)")
    r = subprocess.run([sys.executable, "-c", code, str(lib)], env={**os.environ, "LD_BIND_NOW": "1"},
                       capture_output=True, text=True, timeout=patient(60))
    assert r.returncode == 0 and r.stdout.strip() == "True", r.stdout + r.stderr


@pytest.mark.parametrize("name", ALL_FMUS)
def test_platform_and_version_strings(name, unzipped):
    fmu = unzipped(name)
    assert fmu.fmi2GetVersion() == b"2.0"
    assert fmu.fmi2GetTypesPlatform() == b"default"


# --- the Windows binary ---

def _win64_dll(name, unzipped) -> Path:
    if not WIN64_BUILT:
        pytest.skip("no win64 binary built (IPMSM_WIN64=OFF, or the sanitizer build)")
    fmu = unzipped(name)
    dll = fmu.dir / "binaries" / "win64" / f"{fmu.id}.dll"
    assert dll.is_file(), f"{dll.name} is missing from {fmu.fmu.name} (IPMSM_WIN64=OFF skips this test)"
    return dll


def _pe_headers(dll: Path) -> str:
    objdump = shutil.which("x86_64-w64-mingw32-objdump")
    assert objdump, "x86_64-w64-mingw32-objdump is missing: scripts/setup_win64.sh installs mingw-w64"
    return subprocess.run([objdump, "-p", str(dll)], check=True, capture_output=True, text=True).stdout


@pytest.mark.parametrize("name", ALL_FMUS)
def test_carries_linux64_and_win64(name):
    if not WIN64_BUILT:
        pytest.skip("no win64 binary built (IPMSM_WIN64=OFF, or the sanitizer build)")
    from fmpy import supported_platforms
    assert {"linux64", "win64"} <= set(supported_platforms(str(fmu_path(name))))


@pytest.mark.parametrize("name", ALL_FMUS)
def test_win64_exports_exactly_the_fmi2_functions(name, unzipped):
    pe = _pe_headers(_win64_dll(name, unzipped))
    assert "file format pei-x86-64" in pe and "Characteristics" in pe
    table = pe.split("[Ordinal/Name Pointer] Table", 1)
    assert len(table) == 2, "no export table"
    exported = set(re.findall(r"^\s*\[\s*\d+\] (\S+)$", table[1].split("\n\n", 1)[0], re.MULTILINE))
    assert exported == raw.FMI2_FUNCTIONS, (exported - raw.FMI2_FUNCTIONS, raw.FMI2_FUNCTIONS - exported)


@pytest.mark.parametrize("name", ALL_FMUS)
def test_win64_imports_only_windows_system_dlls(name, unzipped):
    """-static: no libstdc++-6.dll, libgcc_s_seh-1.dll or libwinpthread-1.dll to ship beside it."""
    imported = set(re.findall(r"DLL Name: (\S+)", _pe_headers(_win64_dll(name, unzipped))))
    assert imported and all(WINDOWS_SYSTEM_DLLS.fullmatch(d) for d in imported), imported
    assert any(d.lower() == "kernel32.dll" for d in imported), imported


# --- the model description against the code ---

def _parse_start(v):
    if v.type == "Real":
        return float(v.start)
    if v.type == "Integer":
        return int(v.start)
    if v.type == "Boolean":
        return v.start in ("true", "1")
    return v.start


WRONG_TYPE = {"Real": "Integer", "Integer": "Real", "Boolean": "Real", "String": "Real"}


def _get_as(inst, v, fmi_type):
    ref = raw.vrs([v.valueReference])
    if fmi_type == "Real":
        return inst.fmu.fmi2GetReal(inst.c, ref, 1, raw.reals([0.0]))
    if fmi_type == "Integer":
        return inst.fmu.fmi2GetInteger(inst.c, ref, 1, raw.ints([0]))
    if fmi_type == "Boolean":
        return inst.fmu.fmi2GetBoolean(inst.c, ref, 1, raw.ints([0]))
    return inst.fmu.fmi2GetString(inst.c, ref, 1, (raw.C.c_char_p * 1)())


@pytest.mark.parametrize("name", ALL_FMUS)
def test_model_description_matches_the_binary(name, unzipped):
    fmu = unzipped(name)
    md = fmu.md
    variables = md.modelVariables
    assert [v.valueReference for v in variables] == list(range(len(variables)))
    assert len({v.name for v in variables}) == len(variables)
    with raw.Instance(fmu, "probe") as inst:
        assert inst.setup() == raw.OK and inst.enter() == raw.OK
        initial = {}
        for v in variables:
            status, value = inst.get_status(v.name)
            assert status == raw.OK, f"{v.name}: get in Initialization Mode: {raw.STATUS[status]}\n{inst.log.text()}"
            assert _get_as(inst, v, WRONG_TYPE[v.type]) == raw.ERROR, f"{v.name} readable as {WRONG_TYPE[v.type]}"
            if v.causality in ("parameter", "input"):
                assert v.start is not None, v.name
                assert value == _parse_start(v), f"{v.name}: XML start {v.start!r}, binary {value!r}"
                assert inst.set_status(v.name, value) == raw.OK, v.name
            else:
                assert v.start is None and v.initial == "calculated", v.name
                assert inst.set_status(v.name, value) == raw.ERROR, f"{v.name} ({v.causality}) accepted a set"
                initial[v.name] = value
        unknown = raw.vrs([len(variables)])
        assert inst.fmu.fmi2GetReal(inst.c, unknown, 1, raw.reals([0.0])) == raw.ERROR
        assert inst.exit() in (raw.OK, raw.WARNING), inst.log.text()
        for v in variables:
            status, value = inst.get_status(v.name)
            assert status == raw.OK
            if v.name in initial:
                # an InitialUnknown: what Initialization Mode showed is what initialisation gave
                assert repr(value) == repr(initial[v.name]), (v.name, initial[v.name], value)
            if v.causality == "parameter":
                expected = raw.ERROR if v.variability == "fixed" else raw.OK
                assert inst.set_status(v.name, value) == expected, f"{v.name} ({v.variability})"
            elif v.causality == "input":
                assert inst.set_status(v.name, value) == raw.OK, v.name
        assert inst.step() in (raw.OK, raw.WARNING), inst.log.text()


@pytest.mark.parametrize("name", REAL_FMUS)
def test_initial_unknowns_follow_the_inputs_in_initialization_mode(name, unzipped):
    """A master propagating values in Initialization Mode (libcosim, container FMUs) sees outputs
    that depend on what it set, identical to those after fmi2ExitInitializationMode."""
    fmu = unzipped(name)
    settings = {"IpmsmController": dict(w_m=600.0, i_d=-40.0, i_q=120.0, T_ref=80.0),
                "IpmsmPlant": dict(T_magnet=353.15, w_m=300.0, i_d_start=-20.0),
                "IpmsmDrive": dict(T_magnet=353.15, w_m=300.0, i_d_start=-20.0, T_ref=80.0)}[name]
    with raw.Instance(fmu, "a") as a:
        assert a.setup() == raw.OK and a.enter() == raw.OK
        before = a.outputs()
        a.set(**settings)
        during = a.outputs()
        assert during != before
        assert a.exit() in (raw.OK, raw.WARNING)
        after = a.outputs()
    assert repr(during) == repr(after)


@pytest.mark.parametrize("name", REAL_FMUS)
def test_declared_capabilities(name):
    md = read_model_description(str(fmu_path(name)))
    cs = md.coSimulation
    assert md.fmiVersion == "2.0" and md.modelExchange is None and cs.modelIdentifier == name
    assert cs.canHandleVariableCommunicationStepSize and cs.canGetAndSetFMUstate and cs.canSerializeFMUstate
    assert not cs.canBeInstantiatedOnlyOncePerProcess and not cs.needsExecutionTool
    assert not cs.canInterpolateInputs and not cs.providesDirectionalDerivative and not cs.canRunAsynchronuously
    assert md.description and md.generationTool == "ipmsm-fmu" and md.version
    de = md.defaultExperiment
    # the drive's default is a vehicle tool's step (any multiple of its sample_time)
    step = 1e-3 if name == "IpmsmDrive" else 1e-4
    assert de is not None and float(de.startTime) == 0.0 and float(de.stepSize) == step
    assert float(de.stopTime) > float(de.stepSize)
    units = {u.name: u for u in md.unitDefinitions}
    for v in md.modelVariables:
        assert v.description, f"{v.name} has no description"
        if v.unit:
            assert v.unit in units, f"{v.name}: unit {v.unit} is not defined"
        if v.displayUnit:
            assert v.displayUnit in [d.name for d in units[v.unit].displayUnits], v.name
        if v.unit == "K":
            assert v.displayUnit == "degC", f"{v.name}: a temperature is shown in degC"
    assert md.modelVariables and md.outputs and md.initialUnknowns


@pytest.mark.parametrize("name", REAL_FMUS)
def test_every_output_declares_its_dependencies(name):
    """Importers (OMSimulator) take an output without `dependencies` as depending on every input
    and see an algebraic loop between the controller and the plant. Outputs are computed in
    doStep only: none depends on an input at a communication point. At initialisation the plant's
    currents do not depend on its voltages (so the plant -> controller -> plant chain has no loop)."""
    md = read_model_description(str(fmu_path(name)))
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    assert [u.variable for u in md.outputs] == outputs
    for u in md.outputs:
        assert u.dependencies == [], (u.variable.name, u.dependencies)
    assert [u.variable for u in md.initialUnknowns] == outputs
    for u in md.initialUnknowns:
        assert u.dependencies is not None, u.variable.name
        assert all(d.causality in ("input", "parameter") for d in u.dependencies), u.variable.name
    if name == "IpmsmPlant":
        deps = {u.variable.name: {d.name for d in u.dependencies if d.causality == "input"} for u in md.initialUnknowns}
        assert deps["i_d"] == deps["i_q"] == {"T_magnet"}
        assert deps["P_elec"] == {"u_d", "u_q", "T_magnet"}
    if name == "IpmsmController":
        deps = {u.variable.name: {d.name for d in u.dependencies if d.causality == "input"} for u in md.initialUnknowns}
        assert {"i_d", "i_q"} <= deps["u_d_ref"]  # the flying start holds the measured current


# --- the model description against the contract ---

def _contract_tables():
    """{fmu: {variable: (causality, type, unit)}} from the INTERFACE.md tables (type, unit may be '')."""
    text = (ROOT / "docs" / "spec" / "INTERFACE.md").read_text()
    tables = {}
    for name in REAL_FMUS:
        section = text.split(f"## {name}", 1)[1].split("\n## ", 1)[0]
        rows = {}
        for line in section.splitlines():
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if len(cells) < 5 or not cells[0].startswith("`"):
                continue
            names = re.findall(r"`([^`]+)`", cells[0])
            units = [u.strip() for u in cells[3].split(",")] if cells[3] else [""]
            for i, n in enumerate(names):
                unit = units[i] if len(units) == len(names) else units[0]
                rows[n] = (cells[1], cells[2], unit)
        tables[name] = rows
    return tables


@pytest.mark.parametrize("name", REAL_FMUS)
def test_contract_names_causality_types_units(name):
    contract = _contract_tables()[name]
    assert len(contract) >= 10
    v = {x.name: x for x in read_model_description(str(fmu_path(name))).modelVariables}
    for n, (causality, fmi_type, unit) in contract.items():
        assert n in v, f"the contract's {n} is missing"
        assert v[n].causality == causality, (n, v[n].causality, causality)
        if fmi_type:
            assert v[n].type == fmi_type, (n, v[n].type, fmi_type)
        if unit:
            assert (v[n].unit or "") == unit, (n, v[n].unit, unit)
        if v[n].unit == "rad/s" and n == "w_m":
            assert v[n].displayUnit == "rpm"


# --- documentation ---

@pytest.mark.parametrize("name,method_words", [
    ("IpmsmController", ["Ferrari", "MTPA", "flux map", "current regulator"]),
    ("IpmsmPlant", ["CVODE", "flux map", "inverse"]),
    ("IpmsmDrive", ["coupling description", "sample_time", "Inverter", "whole multiple", "means"]),
])
def test_documentation_explains_method_and_every_variable(name, method_words):
    with zipfile.ZipFile(fmu_path(name)) as z:
        page = z.read("documentation/index.html").decode()
    text = html.unescape(re.sub(r"<[^>]+>", " ", page))
    for w in method_words:
        assert w in text, f"documentation/index.html of {name} does not mention {w!r}"
    md = read_model_description(str(fmu_path(name)))
    rows = re.findall(r"<tr><td><code>([^<]+)</code></td><td>(\d+)</td>", page)
    documented = {html.unescape(n): int(vr) for n, vr in rows}
    for v in md.modelVariables:
        assert documented.get(v.name) == v.valueReference, f"{v.name} is not in the variable reference"
        assert html.escape(v.description, quote=True) in page or v.description in text, v.name
