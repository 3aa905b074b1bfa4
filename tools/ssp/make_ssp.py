"""Writes the SSP package of the two-FMU drive (SSP 1.0): build/ssp/IpmsmControllerPlant.ssp.

    python tools/ssp/make_ssp.py CONTROLLER.fmu PLANT.fmu OUT.ssp [--coupling FILE] [--osp FILE]

- resources/: both FMUs as built.
- SystemStructure.ssd: one component per unit of the coupling description
  (fmu_src/coupling/ipmsm_drive.coupling: the one source of the connections), with a connector
  for every coupled input, every output and every parameter of its FMU but the String ones, the
  description's connections, and one parameter binding per component: every non-String
  parameter at the FMU's default and every other input at its start value. The external
  inputs' start values (T_ref, w_m, u_dc, T_magnet, T_winding) are the OSP structure's initial
  values (scenarios/cosim/osp/OspSystemStructure.xml: the one place the coupled drive's start
  point is written), so the two packages start alike; inputs outside the description keep
  their FMU's start.
- The 100 us step where each tool reads it: OMSimulator the system's `oms:FixedStepMaster`,
  libcosim the default experiment's `osp:FixedStepAlgorithm baseStepSize` (SSP 1.0 has no step
  size of its own); fmpy's simulate_ssp takes it as an argument.

Why the system has no connectors: the SSP readers on hand disagree on them, and the package is
to run as shipped in each. libcosim reads no connection from a system connector ("No such node
(<xmlattr>.startElement)"); fmpy's simulate_ssp sets every input connector of a component to 0
before the first step (T_magnet = 0 K is refused) and needs every listed input connected; and
OMSimulator feeds unconnected system inputs 0 and imports no String connector. So the vehicle
side's inputs are the components' own inputs, started by the parameter bindings (libcosim and
OMSimulator apply bindings to inputs; fmpy applies none, and the FMUs' start values are the same
but for w_m), set by a tool by component and name (controller.T_ref; w_m to both components, as
the description says). The flux map is each FMU's String parameter flux_map: empty, the map in
its resources/; a tool that sets Strings points both at another file.

CMake runs it (target IpmsmControllerPlant_ssp) whenever an FMU, the description or the OSP
structure changes.
"""
from __future__ import annotations

import argparse
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

from fmpy import read_model_description

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from scenarios.cosim.coupling import COUPLING_FILE, Coupling  # noqa: E402

NS = ('xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
      'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
      'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"')
OMS_NS = "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd"
OSP_NS = "http://opensimulationplatform.com/SSP/OSPAnnotations"
OSP_STRUCTURE = ROOT / "scenarios" / "cosim" / "osp" / "OspSystemStructure.xml"
OSP_STRUCTURE_NS = {"osp": "http://opensimulationplatform.com/MSMI/OSPSystemStructure"}
SYSTEM = "IpmsmControllerPlant"
STOP_TIME = 1.0  # s, a default experiment's length (tools let the user change it)
#: the FMI types a connector or a binding may have in every tool (no String: OMSimulator 3)
TYPES = ("Real", "Integer", "Boolean", "Enumeration")


def _kind(v) -> str:
    return "Integer" if v.type == "Enumeration" else v.type


def _connector(v) -> str:
    unit = f" unit={quoteattr(v.unit)}" if v.type == "Real" and v.unit else ""
    return (f'          <ssd:Connector name={quoteattr(v.name)} kind="{v.causality}">'
            f'<ssc:{_kind(v)}{unit}/></ssd:Connector>')


def _parameter(v, value) -> str:
    if v.type == "Boolean":
        value = "true" if str(value).lower() in ("1", "true") else "false"
    elif v.type == "Real":
        value = repr(float(value))
    return (f'                  <ssv:Parameter name={quoteattr(v.name)}><ssv:{_kind(v)} '
            f'value={quoteattr(str(value))}/></ssv:Parameter>')


def osp_initial_values(path: Path = OSP_STRUCTURE) -> dict[tuple[str, str], float]:
    """(simulator, variable) -> the OSP structure's initial value (Reals)."""
    root = ET.parse(path).getroot()
    out = {}
    for sim in root.iterfind(".//osp:Simulator", OSP_STRUCTURE_NS):
        for iv in sim.iterfind("osp:InitialValues/osp:InitialValue", OSP_STRUCTURE_NS):
            out[(sim.get("name"), iv.get("variable"))] = float(iv.find("osp:Real", OSP_STRUCTURE_NS).get("value"))
    return out


def external_starts(coupling: Coupling, osp: dict[tuple[str, str], float]) -> dict[tuple[str, str], float]:
    """(unit, input) -> start value of every input an external input feeds: the OSP structure's,
    the same for all inputs one external input feeds."""
    out = {}
    for e in coupling.inputs:
        values = {osp.get((t.unit, t.variable)) for t in e.targets}
        if None in values or len(values) != 1:
            raise SystemExit(f"{OSP_STRUCTURE}: the external input {e.name} needs one initial value on each of "
                             f"{', '.join(t.text for t in e.targets)}")
        (value,) = values
        out.update({(t.unit, t.variable): value for t in e.targets})
    return out


def system_structure(coupling: Coupling, fmus: dict[str, Path], starts: dict[tuple[str, str], float]) -> str:
    mds = {u.role: read_model_description(str(fmus[u.role])) for u in coupling.units}
    coupled = {(c.target.unit, c.target.variable) for c in coupling.connections}
    x = ['<?xml version="1.0" encoding="UTF-8"?>',
         f'<ssd:SystemStructureDescription {NS} version="1.0" name="{SYSTEM}" generationTool="ipmsm-fmu">',
         f'  <ssd:System name="{SYSTEM}" description="IpmsmController + IpmsmPlant coupled at a fixed step '
         '(Jacobi), as fmu_src/coupling/ipmsm_drive.coupling describes. The vehicle side sets the components\' '
         'inputs ' + ", ".join(f"{e.name} ({', '.join(t.text for t in e.targets)})" for e in coupling.inputs)
         + '; their start values are bound below.">',
         '    <ssd:Elements>']
    for u in coupling.units:
        md = mds[u.role]
        if md.coSimulation.modelIdentifier != u.model_identifier:
            raise SystemExit(f"{fmus[u.role]} is {md.coSimulation.modelIdentifier}, the {u.role} must be "
                             f"{u.model_identifier}")
        x.append(f'      <ssd:Component name="{u.role}" type="application/x-fmu-sharedlibrary" '
                 f'source="resources/{u.model_identifier}.fmu">')
        x.append('        <ssd:Connectors>')
        bound = []
        for v in md.modelVariables:
            if v.type not in TYPES:
                continue
            key = (u.role, v.name)
            if v.causality == "output" or v.causality == "parameter" or key in coupled:
                x.append(_connector(v))
            if v.causality == "parameter":
                bound.append(_parameter(v, v.start))
            elif v.causality == "input" and key not in coupled:
                bound.append(_parameter(v, starts.get(key, v.start)))
        x.append('        </ssd:Connectors>')
        x += ['        <ssd:ParameterBindings>', '          <ssd:ParameterBinding>',
              '            <ssd:ParameterValues>',
              f'              <ssv:ParameterSet version="1.0" name="{u.role} start">',
              '                <ssv:Parameters>', *bound,
              '                </ssv:Parameters>', '              </ssv:ParameterSet>',
              '            </ssd:ParameterValues>', '          </ssd:ParameterBinding>',
              '        </ssd:ParameterBindings>', '      </ssd:Component>']
    x += ['    </ssd:Elements>', '    <ssd:Connections>']
    for c in coupling.connections:
        x.append(f'      <ssd:Connection startElement="{c.source.unit}" startConnector="{c.source.variable}" '
                 f'endElement="{c.target.unit}" endConnector="{c.target.variable}"/>')
    step = repr(coupling.step)
    x += ['    </ssd:Connections>',
          '    <ssd:Annotations>',
          f'      <ssc:Annotation type="org.openmodelica"><oms:Annotations xmlns:oms="{OMS_NS}">'
          f'<oms:SimulationInformation><oms:FixedStepMaster description="oms-ma" stepSize="{step}"/>'
          '</oms:SimulationInformation></oms:Annotations></ssc:Annotation>',
          '    </ssd:Annotations>',
          '  </ssd:System>',
          f'  <ssd:DefaultExperiment startTime="0" stopTime="{STOP_TIME!r}">',
          '    <ssd:Annotations>',
          f'      <ssc:Annotation type="com.opensimulationplatform" xmlns:osp="{OSP_NS}"><osp:Algorithm>'
          f'<osp:FixedStepAlgorithm baseStepSize="{step}"/></osp:Algorithm></ssc:Annotation>',
          '    </ssd:Annotations>',
          '  </ssd:DefaultExperiment>',
          '</ssd:SystemStructureDescription>']
    return "\n".join(x) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("controller", type=Path)
    ap.add_argument("plant", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--coupling", type=Path, default=COUPLING_FILE)
    ap.add_argument("--osp", type=Path, default=OSP_STRUCTURE, help="the OSP structure with the start values")
    a = ap.parse_args(argv)
    coupling = Coupling.read(a.coupling)
    fmus = {"controller": a.controller, "plant": a.plant}
    ssd = system_structure(coupling, fmus, external_starts(coupling, osp_initial_values(a.osp)))
    a.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = a.out.with_suffix(".ssp.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", ssd)
        for u in coupling.units:
            z.write(fmus[u.role], f"resources/{u.model_identifier}.fmu")
    tmp.replace(a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
