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

import datetime
import hashlib
import math
import os
import re
import uuid
from dataclasses import dataclass, field
from typing import Literal, Mapping, Sequence
from xml.sax.saxutils import escape, quoteattr

from pendulab import __version__
from pendulab.fmu.units import DISPLAY_UNITS, check_unit, display_unit, unit_definitions

BaseType = Literal["Real", "Integer", "Boolean"]
GENERATOR = "pendulab"
#: The model description's author and licence (the package's, see pyproject.toml).
AUTHOR = "The pendulab authors"
LICENSE = "MIT"
#: FMI 2.0 ``dependenciesKind`` values; an initial unknown may only be ``dependent`` or ``constant``.
DEPENDENCY_KINDS = ("dependent", "constant", "fixed", "tunable", "discrete")


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
    #: Range (``min``/``max`` in the model description); the FMU refuses a value set outside it.
    min: float | int | None = None
    max: float | int | None = None

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

    @property
    def display_unit(self) -> str | None:
        """The unit the variable is shown in by default (degrees for angles), from the unit table."""
        return display_unit(self.unit) if self.type == "Real" else None


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
    #: Model structure: unknown (output or derivative) -> {known (input or state): dependenciesKind} at
    #: communication points / in continuous time. An unknown missing here depends on every known.
    dependencies: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    #: The same for initialization, where parameters (and states of initial="exact") are knowns too.
    initial_dependencies: Mapping[str, Mapping[str, str]] = field(default_factory=dict)
    #: Conditions between variables (Python/C syntax, see :func:`constraints_c`) and why, checked by the
    #: FMU on leaving initialization.
    constraints: Sequence[tuple[str, str]] = ()
    #: HTML sections of ``documentation/index.html`` particular to the model (equations, states, ...).
    documentation: str = ""

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
        digest.update(repr((sorted(self.constraints),)).encode())
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
    lines += _units_categories_experiment(spec, {v.unit for v in spec.variables if v.unit})
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
    for tag, unknowns, initial in (("Outputs", _outputs(spec), False), ("Derivatives", _derivatives(spec), False),
                                   ("InitialUnknowns", _initial_unknowns(spec), True)):
        lines += _optional_element(
            tag, [f'<Unknown index="{index[v.name]}"{_dependency_attributes(spec, v, index, initial)}/>' for v in unknowns], "    ")
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
    lines += _units_categories_experiment(spec, {v.unit for v in spec.variables if v.unit} | {"s"})
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
    for tag, unknowns, initial in (("Output", _outputs(spec), False), ("ContinuousStateDerivative", _derivatives(spec), False),
                                   ("InitialUnknown", _initial_unknowns(spec), True)):
        lines += [f'    <{tag} valueReference="{refs[v.name]}"{_dependency_attributes(spec, v, refs, initial)}/>' for v in unknowns]
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
        f"author={quoteattr(AUTHOR)}",
        f'version="{__version__}"',
        f"copyright={quoteattr(copyright_notice())}",
        f'license="{LICENSE}"',
        f'generationTool="{GENERATOR} {__version__}"',
        f'generationDateAndTime="{generation_time().strftime("%Y-%m-%dT%H:%M:%SZ")}"',
        'variableNamingConvention="structured"',
        *extra,
    ]
    return ['<?xml version="1.0" encoding="UTF-8"?>', "<fmiModelDescription", *(f"  {a}" for a in attributes[:-1]),
            f"  {attributes[-1]}>"]


def _units_categories_experiment(spec: ModelSpec, units: set[str]) -> list[str]:
    """The elements between the interfaces and the variables, the same in FMI 2.0 and 3.0."""
    for v in spec.variables:
        check_unit(v.unit, f"{spec.identifier}.{v.name}")
    lines = ["  <UnitDefinitions>", *unit_definitions(sorted(units), "    "), "  </UnitDefinitions>"] if units else []
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
        if v.display_unit:
            attrs.append(f"displayUnit={quoteattr(v.display_unit)}")
    for name, bound in (("min", v.min), ("max", v.max)):
        if bound is not None:
            attrs.append(f'{name}="{_literal(bound)}"')
    if derivative is not None:
        attrs.append(f'derivative="{derivative}"')
    if v.start is not None:
        if isinstance(v.start, float) and not math.isfinite(v.start):
            raise ValueError(f"start value of {v.name} must be finite")
        attrs.append(f'start="{_literal(v.start)}"')
    return attrs


def parameter_variables(table: type) -> list[Variable]:
    """The parameters of a parameter table (a dataclass of :func:`pendulab.model.parameters._p` fields, e.g.
    :class:`~pendulab.model.parameters.PlantParameters`) as FMU variables, with their unit, description and
    range (a bound only where it is finite)."""
    def finite(bound: float) -> float | None:
        return float(bound) if math.isfinite(bound) else None

    return [Variable(f.name, "Real", "parameter", start=float(f.default), unit=f.metadata["unit"],
                     description=f.metadata["description"], initial="exact",
                     min=finite(f.metadata["min"]), max=finite(f.metadata["max"]))
            for f in table.__dataclass_fields__.values()]


def _outputs(spec: ModelSpec) -> list[Variable]:
    return [v for v in spec.variables if v.causality == "output"]


def _derivatives(spec: ModelSpec) -> list[Variable]:
    return [v for v in spec.variables if v.derivative_of and spec.model_exchange]


def knowns(spec: ModelSpec, initial: bool) -> list[Variable]:
    """The variables an unknown may depend on: inputs and continuous states; at initialization also the
    variables set before it (``initial="exact"``: parameters, and states started at a given value)."""
    states = set(spec.states)
    return [v for v in spec.variables
            if v.causality == "input" or v.name in states or (initial and v.initial == "exact")]


def _dependency_attributes(spec: ModelSpec, unknown: Variable, refs: Mapping[str, int], initial: bool) -> str:
    """`` dependencies="..." dependenciesKind="..."`` of ``unknown`` (knowns in ``refs``' order), or nothing if
    the spec does not declare them (the unknown then depends on every known)."""
    table = spec.initial_dependencies if initial else spec.dependencies
    if unknown.name not in table:
        return ""
    allowed = {v.name for v in knowns(spec, initial)}
    declared = table[unknown.name]
    for name, kind in declared.items():
        if name not in allowed:
            raise ValueError(f"{spec.identifier}: {unknown.name} cannot depend on {name} (not a known "
                             f"{'at initialization' if initial else 'at communication points'})")
        if kind not in DEPENDENCY_KINDS:
            raise ValueError(f"{spec.identifier}: dependency kind {kind!r} of {unknown.name} on {name}")
    names = sorted(declared, key=lambda n: refs[n])
    # Initialization has no "fixed", "tunable" or "discrete": everything may change there.
    kinds = [declared[n] if not initial or declared[n] == "constant" else "dependent" for n in names]
    return f' dependencies="{" ".join(str(refs[n]) for n in names)}" dependenciesKind="{" ".join(kinds)}"'


def generation_time() -> datetime.datetime:
    """Now in UTC, or ``SOURCE_DATE_EPOCH`` (reproducible builds) if it is set."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch:
        return datetime.datetime.fromtimestamp(int(epoch), datetime.timezone.utc)
    return datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0)


def copyright_notice() -> str:
    return f"Copyright (c) {generation_time().year} {AUTHOR}"


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
        "#include <math.h>",
        "#include <stdio.h>",
        "/* A variable's name and range (words: NULL if it has none) for fmu_common.c's checks and messages. */",
        "typedef struct { const char *name; double min, max; const char *words; } VariableInfo;",
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
        # The range of each variable (fmu_common.c refuses a value set outside it), and its words for the message.
        names = [f"{{{_c_string(v.name)}, {_c_bound(v.min, '-HUGE_VAL')}, {_c_bound(v.max, 'HUGE_VAL')}, "
                 f"{_c_string(range_words(v)) if v.min is not None or v.max is not None else 'NULL'}}}" for v in of_type]
        out.append(f"static const VariableInfo {prefix}_INFO[{size}] = {{{', '.join(names) or '{NULL, 0, 0, NULL}'}}};")
    out.append(constraints_c(spec))
    out.append("#endif")
    return "\n".join(out) + "\n"


def range_words(v: Variable) -> str:
    """``"0.01 to 1000 V"``, with the display unit's range beside (``"0.174533 to 0.261799 rad (10 to 15 deg)"``)."""
    low = "-inf" if v.min is None else f"{v.min:.6g}"
    high = "inf" if v.max is None else f"{v.max:.6g}"
    text = f"{low} to {high}" + (f" {v.unit}" if v.unit and v.unit != "1" else "")
    if v.display_unit and v.min is not None and v.max is not None:
        factor = next(iter(DISPLAY_UNITS[v.unit].values()))
        text += f" ({v.min * factor:.4g} to {v.max * factor:.4g} {v.display_unit})"
    return text


_C_WORDS = {"or": "||", "and": "&&", "not": "!", "abs": "fabs"}


def constraints_c(spec: ModelSpec) -> str:
    """``check_constraints``: C of :attr:`ModelSpec.constraints`, which are written in the common part of
    Python's and C's syntax (names of the spec's variables, numbers, ``+ - * / < <= == >=``, ``or``, ``and``,
    ``abs``). It writes the first violated one, with the values of its variables, into ``message``."""
    arrays = {"Real": "r", "Integer": "i", "Boolean": "b"}
    by_name = {v.name: v for v in spec.variables}
    lines = ["static int check_constraints(const double *r, const int *i, const int *b, char *message, size_t size) {",
             "    (void)r; (void)i; (void)b; (void)message; (void)size;"]
    for condition, why in spec.constraints:
        names = list(dict.fromkeys(n for n in re.findall(r"[A-Za-z_]\w*", condition) if n not in _C_WORDS))
        unknown = [n for n in names if n not in by_name]
        if unknown:
            raise ValueError(f"{spec.identifier}: constraint {condition!r} names {unknown[0]!r}, not a variable")

        def to_c(match: re.Match) -> str:
            word = match.group(0)
            if word in _C_WORDS:
                return _C_WORDS[word]
            v = by_name[word]
            return f"{arrays[v.type]}[VR_{v.identifier}]"

        expression = re.sub(r"[A-Za-z_]\w*", to_c, condition)
        values = ", ".join(f"{n} = %g" for n in names)
        args = "".join(f", (double){arrays[by_name[n].type]}[VR_{by_name[n].identifier}]" for n in names)
        lines.append(f"    if (!({expression})) {{")
        text = f"{condition.replace('%', '%%')} is violated ({values}): {why.replace('%', '%%')}"
        lines.append(f"        snprintf(message, size, {_c_string(text)}{args});")
        lines.append("        return 0;")
        lines.append("    }")
    lines += ["    return 1;", "}"]
    return "\n".join(lines)


def _c_bound(value: float | int | None, missing: str) -> str:
    return missing if value is None else _c_literal(value)


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _c_literal(value: float | int | bool | None, default: float | int = 0) -> str:
    if value is None:
        return str(default)
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


def documentation_html(spec: ModelSpec) -> str:
    """The FMU's ``documentation/index.html``: what the model is (its own sections: equations, state machine,
    ...), then every variable with unit, range and default, and the model structure, all from the spec."""
    def cell(value: object) -> str:
        if value is None:
            return ""
        return escape(f"{value:.6g}" if isinstance(value, float) else _literal(value))  # type: ignore[arg-type]

    rows = []
    for v in spec.variables:
        unit = v.unit + (f" (shown in {v.display_unit})" if v.display_unit else "")
        rows.append(f"<tr><td><code>{escape(v.name)}</code></td><td>{v.causality}</td><td>{v.resolved_variability}</td>"
                    f"<td>{v.type}</td><td>{escape(unit)}</td><td>{cell(v.start)}</td><td>{cell(v.min)}</td>"
                    f"<td>{cell(v.max)}</td><td>{escape(v.description)}</td></tr>")
    structure = []
    for v in _outputs(spec) + _derivatives(spec):
        row = spec.dependencies.get(v.name)
        known = "every input and state" if row is None else ", ".join(f"{escape(k)} ({kind})" for k, kind in row.items()) or "nothing"
        structure.append(f"<tr><td><code>{escape(v.name)}</code></td><td>{known}</td></tr>")
    constraints = "".join(f"<li><code>{escape(c)}</code>: {escape(why)}</li>" for c, why in spec.constraints)
    when = generation_time().strftime("%Y-%m-%d %H:%M:%S UTC")
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{escape(spec.identifier)}: pendulab FMU</title>
<style>
body {{ font-family: sans-serif; max-width: 70em; margin: 2em auto; line-height: 1.4; color: #222; }}
table {{ border-collapse: collapse; margin: 0.5em 0 1.5em; }}
th, td {{ border: 1px solid #bbb; padding: 0.2em 0.5em; text-align: left; vertical-align: top; font-size: 0.9em; }}
th {{ background: #eee; }}
pre {{ background: #f4f4f4; padding: 0.7em; }}
.meta td:first-child {{ font-weight: bold; }}
</style>
</head>
<body>
<h1>{escape(spec.identifier)}</h1>
<p>{escape(spec.description)}</p>
<table class="meta">
<tr><td>FMI version</td><td>{spec.fmi_version}.0 ({"Model Exchange and " if spec.model_exchange else ""}Co-Simulation)</td></tr>
<tr><td>Generated by</td><td>{GENERATOR} {__version__}, {when}</td></tr>
<tr><td>Author</td><td>{escape(AUTHOR)}</td></tr>
<tr><td>Licence</td><td>{LICENSE} ({escape(copyright_notice())})</td></tr>
<tr><td>Default step</td><td>{spec.default_step * 1e3:g} ms</td></tr>
</table>
{spec.documentation}
<h2>Variables</h2>
<p>Units are SI (each defined by its base units in the model description). The FMU refuses a value set outside
[min, max]: the call returns an error and the log names the variable, the value and the range.</p>
<table>
<tr><th>name</th><th>causality</th><th>variability</th><th>type</th><th>unit</th><th>start</th><th>min</th><th>max</th><th>description</th></tr>
{chr(10).join(rows)}
</table>
{f"<h2>Conditions checked at initialization</h2><ul>{constraints}</ul>" if constraints else ""}
<h2>Model structure</h2>
<p>What each output{" and derivative" if spec.model_exchange else ""} depends on directly (the inputs and states
it is computed from at a communication point; the kinds as in the model description).</p>
<table><tr><th>unknown</th><th>depends on</th></tr>
{chr(10).join(structure)}
</table>
</body>
</html>
"""
