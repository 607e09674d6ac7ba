"""Export a :class:`~pendulab.cosim.system.System` as an SSP 1.0 file (System Structure and Parameterization).

The archive holds ``SystemStructure.ssd`` (components, their connectors, start values as inline
parameter sets, and the connections) and the FMUs under ``resources/``, so any SSP tool (fmpy's
``fmpy.ssp``, Ecos, OMSimulator) can load the same loop.

The FMUs may be FMI 2.0 or FMI 3.0 (e.g. the loop with ``Plant3.fmu``, the plant as an FMI 3.0 FMU:
``pendulum_system(..., plant="Plant3")`` or ``pendulab simulate --ssp Plant3``); connectors and
parameters carry SSP's types (FMI 3.0's Float64 is an ``ssc:Real``, Int32 an ``ssc:Integer``).

Every component's start values are an inline parameter set of the same name,
:data:`PARAMETER_SET` (``"initialValues"``): tools that select parameter sets by name apply all of
them at once, e.g. Ecos with ``EcosSimulation(ssp_path=..., step_size=1e-3).init(parameter_set="initialValues")``.

Examples
--------
>>> import tempfile
>>> from pendulab.control import demo_controller, discretize
>>> from pendulab.cosim.pendulum import pendulum_system
>>> from pendulab.model.parameters import PlantParameters
>>> system = pendulum_system(PlantParameters.preset(), discretize(demo_controller(), h=1e-3).to_parameters())
>>> export_ssp(system, Path(tempfile.mkdtemp()) / "loop.ssp").name
'loop.ssp'
"""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import BinaryIO
from xml.sax.saxutils import quoteattr

from fmpy import read_model_description

from pendulab.cosim.system import System
from pendulab.errors import UserError

NAMESPACES = (
    'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
    'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
    'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"'
)

#: Name of the parameter set that holds every component's start values.
PARAMETER_SET = "initialValues"


#: SSP 1.0 type of an FMI variable type (FMI 2.0 names map to themselves).
_SSP_TYPES = {"Float64": "Real", "Float32": "Real", "Int32": "Integer", "Enumeration": "Integer"}


def _ssp_type(fmi_type: str) -> str:
    return _SSP_TYPES.get(fmi_type, fmi_type)


def _value(type_name: str, value: object) -> str:
    if type_name == "Boolean":
        return "true" if value else "false"
    if type_name in ("Integer", "Enumeration"):
        return str(int(value))  # type: ignore[call-overload]
    return repr(float(value))  # type: ignore[arg-type]


def system_structure(system: System, name: str = "pendulab", stop_time: float = 10.0) -> str:
    """The ``SystemStructure.ssd`` text for ``system``."""
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f"<ssd:SystemStructureDescription {NAMESPACES} name={quoteattr(name)} version=\"1.0\" generationTool=\"pendulab\">",
        f"  <ssd:System name={quoteattr(name)}>",
        "    <ssd:Elements>",
    ]
    for component in system.components.values():
        description = read_model_description(str(component.fmu))
        variables = {v.name: v for v in description.modelVariables}
        lines.append(
            f"      <ssd:Component name={quoteattr(component.name)} type=\"application/x-fmu-sharedlibrary\""
            f" source=\"resources/{component.fmu.name}\">"
        )
        lines.append("        <ssd:Connectors>")
        for v in description.modelVariables:
            if v.causality in ("input", "output"):
                unit = f" unit={quoteattr(v.unit)}" if v.unit and _ssp_type(v.type) == "Real" else ""
                type_name = _ssp_type(v.type)
                lines.append(
                    f"          <ssd:Connector name={quoteattr(v.name)} kind=\"{v.causality}\"><ssc:{type_name}{unit}/></ssd:Connector>"
                )
        lines.append("        </ssd:Connectors>")
        if component.start_values:
            lines += [
                "        <ssd:ParameterBindings>",
                "          <ssd:ParameterBinding>",
                "            <ssd:ParameterValues>",
                f"              <ssv:ParameterSet version=\"1.0\" name={quoteattr(PARAMETER_SET)}>",
                "                <ssv:Parameters>",
            ]
            for var, value in component.start_values.items():
                type_name = _ssp_type(variables[var].type) if var in variables else "Real"
                lines.append(
                    f"                  <ssv:Parameter name={quoteattr(var)}><ssv:{type_name} value=\"{_value(type_name, value)}\"/></ssv:Parameter>"
                )
            lines += [
                "                </ssv:Parameters>",
                "              </ssv:ParameterSet>",
                "            </ssd:ParameterValues>",
                "          </ssd:ParameterBinding>",
                "        </ssd:ParameterBindings>",
            ]
        lines.append("      </ssd:Component>")
    lines.append("    </ssd:Elements>")
    lines.append("    <ssd:Connections>")
    for c in system.connections:
        if c.delay:
            # SSP 1.0 connections carry no delay; an importer would silently run a different loop.
            raise UserError(f"connection {c} has a transport delay, which SSP cannot express; export the loop with --delay 0")
        lines.append(
            f"      <ssd:Connection startElement={quoteattr(c.source)} startConnector={quoteattr(c.source_variable)}"
            f" endElement={quoteattr(c.target)} endConnector={quoteattr(c.target_variable)}/>"
        )
    lines.append("    </ssd:Connections>")
    lines.append("  </ssd:System>")
    lines.append(f'  <ssd:DefaultExperiment startTime="0" stopTime="{stop_time!r}"/>')
    lines.append("</ssd:SystemStructureDescription>")
    return "\n".join(lines) + "\n"


def export_ssp(system: System, path: str | Path, name: str = "pendulab", stop_time: float = 10.0) -> Path:
    """Write ``system`` with its FMUs to an ``.ssp`` archive (atomically) and return its path."""
    from pendulab.analysis.results import atomic_write

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ssd = system_structure(system, name, stop_time)  # reads every FMU first: a bad one fails before any file exists

    def write(f: BinaryIO) -> None:
        with zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("SystemStructure.ssd", ssd)
            for fmu in dict.fromkeys(c.fmu for c in system.components.values()):
                zf.write(fmu, f"resources/{fmu.name}")

    # The same temporary-then-rename writer as run.mat: normal file permissions, never a partial file.
    return atomic_write(path, write)
