"""Small data classes that describe an FMU's variables, and the two files written from them.

One variable table per model (in ``pendulab/fmu/models/<name>/config.py``) produces both the
``modelDescription.xml`` (FMI 2.0 or FMI 3.0) and the C header ``variables.h`` with the value references,
so the two can never disagree.

FMI 3.0 value references are unique across types; they are the FMI 2.0 ones shifted per type, in the
order Float64 (= Real), Int32 (= Integer), Boolean, then ``time`` and the event indicators (FMI 3.0
declares each event indicator as a variable). :meth:`ModelSpec.value_references_fmi3` gives them, and
``variables.h`` carries the offsets (``VR3_...``) that ``fmi3_wrapper.c`` maps back.

Examples
--------
>>> v = Variable("V", "Real", causality="input", start=0.0, unit="V", description="Voltage command")
>>> v.causality
'input'
"""

from __future__ import annotations

import hashlib
import math
import re
import uuid
from dataclasses import dataclass, field
from typing import Literal, Sequence
from xml.sax.saxutils import quoteattr

BaseType = Literal["Real", "Integer", "Boolean"]
GENERATOR = "pendulab"


@dataclass(frozen=True)
class Variable:
    """One scalar variable of an FMU (FMI 2.0 ``ScalarVariable``)."""

    name: str
    type: BaseType
    causality: str = "local"  # parameter | input | output | local | calculatedParameter
    variability: str | None = None  # default: fixed for parameters, discrete for non-Real, else continuous
    start: float | int | bool | None = None
    unit: str = ""
    description: str = ""
    initial: str | None = None
    derivative_of: str | None = None  # name of the state this is the derivative of
    c_name: str | None = None  # identifier in variables.h (default: name with non-identifier characters replaced)

    @property
    def resolved_variability(self) -> str:
        if self.variability:
            return self.variability
        if self.causality == "parameter":
            return "fixed"
        return "continuous" if self.type == "Real" else "discrete"

    @property
    def identifier(self) -> str:
        return self.c_name or re.sub(r"\W+", "_", self.name).strip("_")


@dataclass
class ModelSpec:
    """Everything the builder needs for one FMU.

    Attributes
    ----------
    identifier : str
        Model identifier: the binary's name and the ``.fmu`` file's stem.
    states : sequence of str
        Names of the continuous states; empty for a Co-Simulation-only model.
    sources : list of str
        C files (in the model folder or generated) compiled with the shared wrapper.
    generated : dict
        Extra files written at build time (file name -> text), e.g. CasADi's generated C.
    defines : dict
        Extra ``#define`` lines for ``variables.h``.
    """

    identifier: str
    description: str
    variables: list[Variable]
    states: Sequence[str] = ()
    sources: list[str] = field(default_factory=lambda: ["model.c"])
    generated: dict[str, str] = field(default_factory=dict)
    defines: dict[str, str] = field(default_factory=dict)
    default_step: float = 1e-3
    #: Number of event indicators (Model Exchange); the model implements model_get_event_indicators.
    event_indicators: int = 0
    #: canHandleVariableCommunicationStepSize: False if doStep accepts only ``default_step``.
    variable_step: bool = True
    #: Names of the event indicators (FMI 3.0 declares each as a variable); default ``z1``, ``z2``, ...
    event_indicator_names: Sequence[str] = ()
    #: FMI version of the FMU built from this spec: 2 (``fmi2_wrapper.c``) or 3 (``fmi3_wrapper.c``).
    fmi_version: int = 2

    @property
    def model_exchange(self) -> bool:
        return bool(self.states)

    def value_references(self) -> dict[str, int]:
        """Value references: consecutive per base type, in table order."""
        counters: dict[str, int] = {"Real": 0, "Integer": 0, "Boolean": 0}
        refs = {}
        for v in self.variables:
            refs[v.name] = counters[v.type]
            counters[v.type] += 1
        return refs

    def count(self, base_type: str) -> int:
        return sum(v.type == base_type for v in self.variables)

    def indicator_names(self) -> list[str]:
        names = list(self.event_indicator_names) or [f"z{k + 1}" for k in range(self.event_indicators)]
        if len(names) != self.event_indicators:
            raise ValueError(f"{self.identifier}: {len(names)} event indicator names for {self.event_indicators} indicators")
        return names

    def fmi3_offsets(self) -> dict[str, int]:
        """First FMI 3.0 value reference of each group (see the module docstring)."""
        offsets, next_ref = {}, 0
        for group, size in (("Real", self.count("Real")), ("Integer", self.count("Integer")),
                            ("Boolean", self.count("Boolean")), ("time", 1), ("indicators", self.event_indicators)):
            offsets[group] = next_ref
            next_ref += size
        return offsets

    def value_references_fmi3(self) -> dict[str, int]:
        """FMI 3.0 value references (unique across types), including ``time`` and the event indicators."""
        offsets = self.fmi3_offsets()
        refs = {v.name: offsets[v.type] + ref for v, ref in zip(self.variables, self.value_references().values())}
        refs["time"] = offsets["time"]
        for k, name in enumerate(self.indicator_names()):
            refs[f"event_indicator.{name}"] = offsets["indicators"] + k
        return refs

    @property
    def guid(self) -> str:
        """A GUID that changes whenever the variables or the generated code change."""
        digest = hashlib.sha256()
        for v in self.variables:
            digest.update(repr(v).encode())
        for name in sorted(self.generated):
            digest.update(name.encode() + self.generated[name].encode())
        if self.fmi_version != 2:  # FMI 2.0 GUIDs stay as they were before FMI 3.0 existed
            digest.update(f"fmi{self.fmi_version}".encode())
        return "{" + str(uuid.UUID(bytes=digest.digest()[:16])) + "}"


def _literal(value: float | int | bool) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


def model_description_xml(spec: ModelSpec, source_files: Sequence[str]) -> str:
    """The ``modelDescription.xml`` text (FMI 2.0, or FMI 3.0 if ``spec.fmi_version == 3``)."""
    if spec.fmi_version == 3:
        return model_description_fmi3_xml(spec)
    refs = spec.value_references()
    index = {v.name: k + 1 for k, v in enumerate(spec.variables)}
    files = "".join(f'\n      <File name="{name}"/>' for name in source_files)
    lines = _root_element(spec, "2.0", "guid", f'numberOfEventIndicators="{spec.event_indicators}"')
    if spec.model_exchange:
        lines.append(
            f'  <ModelExchange modelIdentifier="{spec.identifier}" canNotUseMemoryManagementFunctions="true">'
            f"\n    <SourceFiles>{files}\n    </SourceFiles>\n  </ModelExchange>"
        )
    lines.append(
        f'  <CoSimulation modelIdentifier="{spec.identifier}" canHandleVariableCommunicationStepSize="{_literal(spec.variable_step)}"'
        f' canNotUseMemoryManagementFunctions="true">'
        f"\n    <SourceFiles>{files}\n    </SourceFiles>\n  </CoSimulation>"
    )
    lines += _units_categories_experiment(spec, sorted({v.unit for v in spec.variables if v.unit}))
    lines.append("  <ModelVariables>")
    for v in spec.variables:
        # FMI 2.0: the variable's attributes on ScalarVariable, its type's (unit, derivative, start) inside.
        inner = _type_attributes(v, index[v.derivative_of] if v.derivative_of else None)
        lines.append(f"    <!-- {index[v.name]} -->")
        lines.append(f"    <ScalarVariable {' '.join(_variable_attributes(v, refs[v.name]))}>")
        lines.append(f"      <{v.type} {' '.join(inner)}/>")
        lines.append("    </ScalarVariable>")
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    for tag, unknowns in (("Outputs", [v for v in spec.variables if v.causality == "output"]),
                          ("Derivatives", [v for v in spec.variables if v.derivative_of]),
                          ("InitialUnknowns", _initial_unknowns(spec))):
        lines += _optional_element(tag, [f'<Unknown index="{index[v.name]}"/>' for v in unknowns], "    ")
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


_FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}


def model_description_fmi3_xml(spec: ModelSpec) -> str:
    """The FMI 3.0 ``modelDescription.xml`` text from the same variable table as the FMI 2.0 one.

    Model Exchange (where the model has states) and Co-Simulation in one FMU. FMI 3.0 has no source file
    list here: ``sources/buildDescription.xml`` lists them.
    """
    refs = spec.value_references_fmi3()
    indicators = [f"event_indicator.{n}" for n in spec.indicator_names()] if spec.model_exchange else []
    lines = _root_element(spec, "3.0", "instantiationToken")
    if spec.model_exchange:
        lines.append(f'  <ModelExchange modelIdentifier="{spec.identifier}"/>')
    lines.append(
        f'  <CoSimulation modelIdentifier="{spec.identifier}"'
        f' canHandleVariableCommunicationStepSize="{_literal(spec.variable_step)}"/>'
    )
    # time is a variable of unit s in FMI 3.0
    lines += _units_categories_experiment(spec, sorted({v.unit for v in spec.variables if v.unit} | {"s"}))
    lines.append("  <ModelVariables>")
    lines.append(f'    <Float64 name="time" valueReference="{refs["time"]}" causality="independent" variability="continuous"'
                 ' description="Simulation time" unit="s"/>')
    for v in spec.variables:
        # FMI 3.0: all attributes on the one element named after the type.
        attrs = _variable_attributes(v, refs[v.name]) + _type_attributes(v, refs[v.derivative_of] if v.derivative_of else None)
        lines.append(f"    <{_FMI3_TYPES[v.type]} {' '.join(attrs)}/>")
    for name, short in zip(indicators, spec.indicator_names()):
        lines.append(f"    <Float64 name={quoteattr(name)} valueReference=\"{refs[name]}\" causality=\"local\" variability=\"continuous\""
                     f" description={quoteattr(f'Event indicator {short}: changes sign where the right-hand side switches')}/>")
    lines.append("  </ModelVariables>")
    lines.append("  <ModelStructure>")
    lines += [f'    <Output valueReference="{refs[v.name]}"/>' for v in spec.variables if v.causality == "output"]
    lines += [f'    <ContinuousStateDerivative valueReference="{refs[v.name]}"/>' for v in spec.variables if v.derivative_of and spec.model_exchange]
    lines += [f'    <InitialUnknown valueReference="{refs[v.name]}"/>' for v in _initial_unknowns(spec)]
    lines += [f'    <EventIndicator valueReference="{refs[name]}"/>' for name in indicators]
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


def _root_element(spec: ModelSpec, fmi_version: str, token: str, *extra: str) -> list[str]:
    """The XML declaration and the opening ``fmiModelDescription`` tag; ``token`` names the GUID's attribute
    (``guid`` in FMI 2.0, ``instantiationToken`` in FMI 3.0), ``extra`` are attributes only one version has."""
    attributes = [
        f'fmiVersion="{fmi_version}"',
        f"modelName={quoteattr(spec.identifier)}",
        f'{token}="{spec.guid}"',
        f"description={quoteattr(spec.description)}",
        f'generationTool="{GENERATOR}"',
        'variableNamingConvention="structured"',
        *extra,
    ]
    return ['<?xml version="1.0" encoding="UTF-8"?>', "<fmiModelDescription", *(f"  {a}" for a in attributes[:-1]),
            f"  {attributes[-1]}>"]


def _units_categories_experiment(spec: ModelSpec, units: Sequence[str]) -> list[str]:
    """The elements between the interfaces and the variables, the same in FMI 2.0 and 3.0."""
    lines = _optional_element("UnitDefinitions", [f"<Unit name={quoteattr(u)}/>" for u in units], "  ")
    lines.append("  <LogCategories>")
    lines.append('    <Category name="logStatusError" description="Errors"/>')
    lines.append('    <Category name="logEvents" description="State changes and events"/>')
    lines.append("  </LogCategories>")
    lines.append(f'  <DefaultExperiment startTime="0" stopTime="10" stepSize="{spec.default_step!r}"/>')
    return lines


def _optional_element(tag: str, children: list[str], indent: str) -> list[str]:
    """``<tag>`` at ``indent`` around ``children`` (one line each, indented a level deeper), or nothing if
    there are none."""
    if not children:
        return []
    return [f"{indent}<{tag}>", *(f"{indent}  {c}" for c in children), f"{indent}</{tag}>"]


def _variable_attributes(v: Variable, ref: int) -> list[str]:
    """A variable's own attributes (name, value reference, description, causality, variability, initial)."""
    attrs = [f"name={quoteattr(v.name)}", f'valueReference="{ref}"']
    if v.description:
        attrs.append(f"description={quoteattr(v.description)}")
    attrs.append(f'causality="{v.causality}"')
    attrs.append(f'variability="{v.resolved_variability}"')
    if v.initial:
        attrs.append(f'initial="{v.initial}"')
    return attrs


def _type_attributes(v: Variable, derivative: int | None) -> list[str]:
    """The attributes of a variable's type: unit, ``derivative`` (the state's index in FMI 2.0, its value
    reference in FMI 3.0) and start."""
    attrs = []
    if v.unit and v.type == "Real":
        attrs.append(f"unit={quoteattr(v.unit)}")
    if derivative is not None:
        attrs.append(f'derivative="{derivative}"')
    if v.start is not None:
        if isinstance(v.start, float) and not math.isfinite(v.start):
            raise ValueError(f"start value of {v.name} must be finite")
        attrs.append(f'start="{_literal(v.start)}"')
    return attrs


def _initial_unknowns(spec: ModelSpec) -> list[Variable]:
    """The unknowns of initialization mode, in table order (the same rule for FMI 2.0 and 3.0)."""
    return [
        v
        for v in spec.variables
        if (v.causality == "output" and v.initial in (None, "calculated", "approx"))
        or v.causality == "calculatedParameter"
        or (v.derivative_of and spec.model_exchange)
    ]


def variables_header(spec: ModelSpec) -> str:
    """The C header ``variables.h``: identifier, GUID, value references and start values."""
    refs = spec.value_references()
    out = [
        f"/* Generated by pendulab from the variable table of {spec.identifier}: do not edit. */",
        "#ifndef PENDULAB_VARIABLES_H",
        "#define PENDULAB_VARIABLES_H",
        f"#define MODEL_IDENTIFIER {spec.identifier}",
        f'#define MODEL_NAME "{spec.identifier}"',
        f'#define MODEL_GUID "{spec.guid}"',
        f"#define N_STATES {len(spec.states)}",
        f"#define N_EVENT_INDICATORS {spec.event_indicators}",
    ]
    for base in ("Real", "Integer", "Boolean"):
        out.append(f"#define N_{base.upper()}S {spec.count(base)}")
    for v in spec.variables:
        out.append(f"#define VR_{v.identifier} {refs[v.name]}  /* {v.type} {v.name} */")
    if spec.fmi_version == 3:
        offsets = spec.fmi3_offsets()
        out.append("/* FMI 3.0 value references: unique across types (fmi3_wrapper.c maps them back) */")
        out += [f"#define VR3_{group.upper()} {first}" for group, first in offsets.items()]
    for name, value in spec.defines.items():
        out.append(f"#define {name} {value}")
    for base, c_type, prefix in (("Real", "double", "REAL"), ("Integer", "int", "INTEGER"), ("Boolean", "int", "BOOLEAN")):
        of_type = [v for v in spec.variables if v.type == base]
        values = [_c_literal(v.start) for v in of_type]
        size = max(1, len(of_type))
        out.append(f"static const {c_type} {prefix}_START[{size}] = {{{', '.join(values) or '0'}}};")
        # Fixed variables (parameters) may only be set before the end of initialization.
        fixed = ["1" if v.resolved_variability in ("fixed", "constant") else "0" for v in of_type]
        out.append(f"static const unsigned char {prefix}_FIXED[{size}] = {{{', '.join(fixed) or '0'}}};")
    out.append("#endif")
    return "\n".join(out) + "\n"


def _c_literal(value: float | int | bool | None) -> str:
    if value is None:
        return "0"
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))
