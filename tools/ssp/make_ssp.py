"""Writes the SSP package of the two-FMU drive (SSP 1.0): build/ssp/IpmsmControllerPlant.ssp.

    python tools/ssp/make_ssp.py CONTROLLER.fmu PLANT.fmu OUT.ssp [--coupling FILE]

- resources/: both FMUs as built.
- SystemStructure.ssd: one component per unit of the coupling description
  (fmu_src/coupling/ipmsm_drive.coupling: the one source of the connections), with a connector
  for every input, output and parameter of its FMU (from its modelDescription.xml) and a
  parameter binding with the FMU's defaults (its start values); the system's connectors are the
  description's external inputs, connected to the inputs they feed; the default experiment is
  the description's step (100 us), given as an OMSimulator annotation (OMSimulator reads its
  fixed step from there; SSP 1.0 has no step size) and as this project's own annotation.

CMake runs it (target IpmsmControllerPlant_ssp) whenever an FMU or the description changes.
"""
from __future__ import annotations

import argparse
import sys
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
SYSTEM = "IpmsmControllerPlant"
STOP_TIME = 1.0  # s, a default experiment's length (tools let the user change it)
KINDS = {"input": "input", "output": "output", "parameter": "parameter"}


def _type(v, prefix: str) -> str:
    kind = "Integer" if v.type == "Enumeration" else v.type
    unit = f" unit={quoteattr(v.unit)}" if prefix == "ssc" and v.type == "Real" and v.unit else ""
    return f"<{prefix}:{kind}{unit}/>"


def _value(v) -> str:
    start = v.start if v.start is not None else ""
    if v.type == "Boolean":
        start = "true" if str(start).lower() in ("1", "true") else "false"
    kind = "Integer" if v.type == "Enumeration" else v.type
    return f"<ssv:{kind} value={quoteattr(str(start))}/>"


def system_structure(coupling: Coupling, fmus: dict[str, Path]) -> str:
    mds = {u.role: read_model_description(str(fmus[u.role])) for u in coupling.units}
    units = {}
    for md in mds.values():
        for u in md.unitDefinitions:
            units.setdefault(u.name, u)
    ext_vars = {}  # external input -> the variable it feeds (its unit)
    for e in coupling.inputs:
        t = e.targets[0]
        ext_vars[e.name] = next(v for v in mds[t.unit].modelVariables if v.name == t.variable)
    x = ['<?xml version="1.0" encoding="UTF-8"?>',
         f'<ssd:SystemStructureDescription {NS} version="1.0" name="{SYSTEM}" generationTool="ipmsm-fmu">',
         f'  <ssd:System name="{SYSTEM}" description="IpmsmController + IpmsmPlant coupled at a fixed step '
         f'(Jacobi), as fmu_src/coupling/ipmsm_drive.coupling describes">',
         '    <ssd:Connectors>']
    for name, v in ext_vars.items():
        x.append(f'      <ssd:Connector name={quoteattr(name)} kind="input">{_type(v, "ssc")}</ssd:Connector>')
    x += ['    </ssd:Connectors>', '    <ssd:Elements>']
    for u in coupling.units:
        md = mds[u.role]
        if md.coSimulation.modelIdentifier != u.model_identifier:
            raise SystemExit(f"{fmus[u.role]} is {md.coSimulation.modelIdentifier}, the {u.role} must be "
                             f"{u.model_identifier}")
        x.append(f'      <ssd:Component name="{u.role}" type="application/x-fmu-sharedlibrary" '
                 f'source="resources/{u.model_identifier}.fmu">')
        x.append('        <ssd:Connectors>')
        params = []
        for v in md.modelVariables:
            if v.causality in KINDS:
                x.append(f'          <ssd:Connector name={quoteattr(v.name)} kind="{KINDS[v.causality]}">'
                         f'{_type(v, "ssc")}</ssd:Connector>')
            if v.causality == "parameter":
                params.append(v)
        x.append('        </ssd:Connectors>')
        x += ['        <ssd:ParameterBindings>', '          <ssd:ParameterBinding>',
              '            <ssd:ParameterValues>',
              f'              <ssv:ParameterSet version="1.0" name="{u.model_identifier} defaults">',
              '                <ssv:Parameters>']
        for v in params:
            x.append(f'                  <ssv:Parameter name={quoteattr(v.name)}>{_value(v)}</ssv:Parameter>')
        x += ['                </ssv:Parameters>', '              </ssv:ParameterSet>',
              '            </ssd:ParameterValues>', '          </ssd:ParameterBinding>',
              '        </ssd:ParameterBindings>', '      </ssd:Component>']
    x += ['    </ssd:Elements>', '    <ssd:Connections>']
    for e in coupling.inputs:
        for t in e.targets:
            x.append(f'      <ssd:Connection startElement="" startConnector="{e.name}" endElement="{t.unit}" '
                     f'endConnector="{t.variable}"/>'.replace('startElement="" ', ''))
    for c in coupling.connections:
        x.append(f'      <ssd:Connection startElement="{c.source.unit}" startConnector="{c.source.variable}" '
                 f'endElement="{c.target.unit}" endConnector="{c.target.variable}"/>')
    x += ['    </ssd:Connections>',
          '    <ssd:Annotations>',
          f'      <ssc:Annotation type="org.openmodelica"><oms:Annotations xmlns:oms="{OMS_NS}">'
          f'<oms:SimulationInformation><oms:FixedStepMaster description="oms-ma" stepSize="{coupling.step!r}"/>'
          '</oms:SimulationInformation></oms:Annotations></ssc:Annotation>',
          f'      <ssc:Annotation type="org.ipmsm-fmu.experiment"><ipmsm:Experiment xmlns:ipmsm="urn:ipmsm-fmu" '
          f'stepSize="{coupling.step!r}" coupling="jacobi"/></ssc:Annotation>',
          '    </ssd:Annotations>',
          '  </ssd:System>']
    x.append(f'  <ssd:DefaultExperiment startTime="0" stopTime="{STOP_TIME!r}"/>')
    x.append('</ssd:SystemStructureDescription>')
    return "\n".join(x) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("controller", type=Path)
    ap.add_argument("plant", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--coupling", type=Path, default=COUPLING_FILE)
    a = ap.parse_args(argv)
    coupling = Coupling.read(a.coupling)
    fmus = {"controller": a.controller, "plant": a.plant}
    ssd = system_structure(coupling, fmus)
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
