"""Export a :class:`~pendulab.cosim.system.System` as an SSP 1.0 file (System Structure and Parameterization).

The archive holds ``SystemStructure.ssd`` (components, their connectors with units, the connections, the unit
definitions, the step size), the parameters as an SSV file ``resources/parameters.ssv`` referenced from the
SSD, and the FMUs under ``resources/``, so SSP tools (fmpy's ``fmpy.ssp``, Ecos, OMSimulator) load the same loop.

The start values are given twice, for the two ways tools read them: once in ``resources/parameters.ssv``,
bound to the system with names ``component.variable`` (fmpy: ``simulate_ssp(..., parameter_set=read_ssv(ssp,
"resources/parameters.ssv"))``), and once inline in each component, as a parameter set of the same name,
:data:`PARAMETER_SET` (Ecos: ``EcosSimulation(ssp_path=..., step_size=1e-3).init(parameter_set="initialValues")``).
Every input that no connection feeds gets a value there too (its FMU's start value), so no tool leaves it to
chance. SSP 1.0 has no step size: it is in the ``DefaultExperiment``'s annotation and the system's description,
and must be given to the tool (``step_size=1e-3``).

The FMUs may be FMI 2.0 or FMI 3.0 (e.g. the loop with ``Plant3.fmu``, the plant as an FMI 3.0 FMU:
``pendulum_system(..., plant="Plant3")`` or ``pendulab simulate --ssp Plant3``); connectors and
parameters carry SSP's types (FMI 3.0's Float64 is an ``ssc:Real``, Int32 an ``ssc:Integer``).

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
from pendulab.fmu.units import unit_definitions

NAMESPACES = (
    'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
    'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
    'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"'
)

#: Name of the parameter set that holds every component's start values.
PARAMETER_SET = "initialValues"
#: The SSV file (in the archive) that holds them for the whole system, named ``component.variable``.
PARAMETER_FILE = "resources/parameters.ssv"
#: Namespace of the annotation that states the communication step and the master's algorithm.
ANNOTATION = "org.pendulab.master"


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


def _parameters(system: System) -> dict[str, dict[str, tuple[str, str]]]:
    """component -> {variable: (SSP type, value text)}: its start values and a value for each input no
    connection feeds (the FMU's own start value)."""
    open_inputs = _open_inputs(system)
    table = {}
    for component in system.components.values():
        variables = {v.name: v for v in read_model_description(str(component.fmu)).modelVariables}
        values = {}
        for v in variables.values():
            if (component.name, v.name) in open_inputs and v.name not in component.start_values:
                values[v.name] = (_ssp_type(v.type), _value(_ssp_type(v.type), v.start if v.start is not None else 0))
        for var, value in component.start_values.items():
            type_name = _ssp_type(variables[var].type) if var in variables else "Real"
            values[var] = (type_name, _value(type_name, value))
        table[component.name] = values
    return table


def _open_inputs(system: System) -> dict[tuple[str, str], tuple[str, str]]:
    """(component, input) -> (SSP type, unit) of every input that no connection feeds."""
    fed = {(c.target, c.target_variable) for c in system.connections}
    return {(component.name, v.name): (_ssp_type(v.type), v.unit if v.unit and _ssp_type(v.type) == "Real" else "")
            for component in system.components.values()
            for v in read_model_description(str(component.fmu)).modelVariables
            if v.causality == "input" and (component.name, v.name) not in fed}


def _parameter_set(values: dict[str, tuple[str, str]], indent: str) -> list[str]:
    lines = [f"{indent}<ssv:ParameterSet version=\"1.0\" name={quoteattr(PARAMETER_SET)}>", f"{indent}  <ssv:Parameters>"]
    lines += [f"{indent}    <ssv:Parameter name={quoteattr(name)}><ssv:{kind} value=\"{text}\"/></ssv:Parameter>"
              for name, (kind, text) in values.items()]
    return lines + [f"{indent}  </ssv:Parameters>", f"{indent}</ssv:ParameterSet>"]


def parameter_values(system: System) -> str:
    """The ``parameters.ssv`` text: every component's values, named ``component.variable``."""
    values = {f"{component}.{name}": value for component, table in _parameters(system).items() for name, value in table.items()}
    lines = ['<?xml version="1.0" encoding="UTF-8"?>']
    body = _parameter_set(values, "")
    body[0] = body[0].replace("<ssv:ParameterSet ", f"<ssv:ParameterSet {NAMESPACES.split(' ')[2]} ")
    return "\n".join(lines + body) + "\n"


def system_structure(system: System, name: str = "pendulab", stop_time: float = 10.0) -> str:
    """The ``SystemStructure.ssd`` text for ``system``."""
    parameters = _parameters(system)
    units: set[str] = set()
    open_inputs = _open_inputs(system)
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f"<ssd:SystemStructureDescription {NAMESPACES} name={quoteattr(name)} version=\"1.0\" generationTool=\"pendulab\">",
        f"  <ssd:System name={quoteattr(name)} description={quoteattr(f'Co-simulation at a fixed step of {system.step!r} s, components evaluated in the order listed (Gauss-Seidel)')}>",
    ]
    lines += [
        "    <ssd:ParameterBindings>",
        f"      <ssd:ParameterBinding source={quoteattr(PARAMETER_FILE)}/>",
        "    </ssd:ParameterBindings>",
        "    <ssd:Elements>",
    ]
    for component in system.components.values():
        description = read_model_description(str(component.fmu))
        lines.append(
            f"      <ssd:Component name={quoteattr(component.name)} type=\"application/x-fmu-sharedlibrary\""
            f" source=\"resources/{component.fmu.name}\">"
        )
        lines.append("        <ssd:Connectors>")
        for v in description.modelVariables:
            # An input no connection feeds is no connector: it keeps the value the parameter set gives it (a
            # tool that drives every input connector, as fmpy 0.3's simulate_ssp does, would drive it with
            # another connection's value).
            if v.causality == "output" or (v.causality == "input" and (component.name, v.name) not in open_inputs):
                type_name = _ssp_type(v.type)
                unit = ""
                if v.unit and type_name == "Real":
                    unit = f" unit={quoteattr(v.unit)}"
                    units.add(v.unit)
                lines.append(
                    f"          <ssd:Connector name={quoteattr(v.name)} kind=\"{v.causality}\"><ssc:{type_name}{unit}/></ssd:Connector>"
                )
        lines.append("        </ssd:Connectors>")
        if parameters[component.name]:
            lines += ["        <ssd:ParameterBindings>", "          <ssd:ParameterBinding>", "            <ssd:ParameterValues>"]
            lines += _parameter_set(parameters[component.name], "              ")
            lines += ["            </ssd:ParameterValues>", "          </ssd:ParameterBinding>", "        </ssd:ParameterBindings>"]
        lines.append("      </ssd:Component>")
    lines.append("    </ssd:Elements>")
    connections = []
    for c in system.connections:
        if c.delay:
            # SSP 1.0 connections carry no delay; an importer would silently run a different loop.
            raise UserError(f"connection {c} has a transport delay, which SSP cannot express; export the loop with --delay 0")
        connections.append(f"<ssd:Connection startElement={quoteattr(c.source)} startConnector={quoteattr(c.source_variable)}"
                           f" endElement={quoteattr(c.target)} endConnector={quoteattr(c.target_variable)}/>")
    if connections:  # the schema wants at least one inside the element
        lines += ["    <ssd:Connections>", *(f"      {c}" for c in connections), "    </ssd:Connections>"]
    lines.append("  </ssd:System>")
    if units:
        lines += ["  <ssd:Units>", *unit_definitions(sorted(units), "    ", prefix="ssc:"), "  </ssd:Units>"]
    lines += [
        f'  <ssd:DefaultExperiment startTime="0" stopTime="{stop_time!r}">',
        "    <ssd:Annotations>",
        f'      <ssc:Annotation type="{ANNOTATION}">',
        f'        <pendulab:Master xmlns:pendulab="http://pendulab.org/ssp" stepSize="{system.step!r}" algorithm="gauss-seidel"'
        f' order={quoteattr(" ".join(system.components))}/>',
        "      </ssc:Annotation>",
        "    </ssd:Annotations>",
        "  </ssd:DefaultExperiment>",
        "</ssd:SystemStructureDescription>",
    ]
    return "\n".join(lines) + "\n"


def export_ssp(system: System, path: str | Path, name: str = "pendulab", stop_time: float = 10.0) -> Path:
    """Write ``system`` with its FMUs to an ``.ssp`` archive (atomically) and return its path."""
    from pendulab.analysis.results import atomic_write

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ssd = system_structure(system, name, stop_time)  # reads every FMU first: a bad one fails before any file exists
    ssv = parameter_values(system)

    def write(f: BinaryIO) -> None:
        with zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED) as zf:
            zf.writestr("SystemStructure.ssd", ssd)
            zf.writestr(PARAMETER_FILE, ssv)
            for fmu in dict.fromkeys(c.fmu for c in system.components.values()):
                zf.write(fmu, f"resources/{fmu.name}")

    # The same temporary-then-rename writer as run.mat: normal file permissions, never a partial file.
    return atomic_write(path, write)
