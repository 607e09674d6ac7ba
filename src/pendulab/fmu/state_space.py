"""FMUs of the CasADi state-space models (the plant, the seesaw): one spec builder and one C model for both.

Each such FMU is ``c/state_space.c`` (Co-Simulation's RK4 sub-steps; Model Exchange's derivatives, event
indicators and event update) around C generated from the model's CasADi functions; its model folder's
``config.py`` says only what differs: names, units, texts, ranges and documentation.

Examples
--------
>>> from pendulab.fmu.build import model_spec
>>> spec = model_spec("Seesaw")
>>> spec.sources, spec.event_indicators
(['state_space.c', 'seesaw_casadi.c'], 12)
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import casadi as ca

from pendulab.fmu.description import ModelSpec, Variable, parameter_variables
from pendulab.fmu.structure import state_space_structure
from pendulab.model.plant import MAX_SUBSTEP

#: The shared C model (in ``fmu/c/``), compiled with each model's generated C.
SOURCE = "state_space.c"
#: The order of the generated functions a model hands over (see ``c/state_space.c``).
FUNCTIONS = ("ode", "outputs", "rk4", "ode_regime", "indicators", "event")


def generate_c(functions: Sequence[ca.Function], directory: Path, stem: str) -> Path:
    """Write the C code of CasADi ``functions`` to ``directory/stem.c`` (and its header ``stem.h``).

    The one code generator of the models' C: the FMUs carry it, and the firmware twin
    (``firmware/twin/gen_plant.py``) links the same text.

    Parameters
    ----------
    functions : sequence of casadi.Function
        The functions, e.g. :attr:`pendulab.model.plant.PlantModel.functions`.
    directory : pathlib.Path
        Where to write (created if missing).
    stem : str
        The files' name without suffix.

    Returns
    -------
    pathlib.Path
        The ``.c`` file.

    Examples
    --------
    >>> import tempfile
    >>> from pendulab.model.seesaw import SeesawModel
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     path = generate_c(SeesawModel().functions, Path(tmp), "seesaw_casadi")
    ...     "seesaw_rk4" in path.read_text(), path.with_suffix(".h").exists()
    (True, True)
    """
    directory.mkdir(parents=True, exist_ok=True)
    generator = ca.CodeGenerator(f"{stem}.c", {"with_header": True, "casadi_real": "double", "casadi_int": "long long int"})
    for function in functions:
        generator.add(function)
    generator.generate(str(directory) + "/")
    return directory / f"{stem}.c"


@dataclass(frozen=True)
class StateSpaceFmu:
    """What one CasADi state-space FMU is made of.

    Attributes
    ----------
    identifier, description : str
        The FMU's model identifier and its one-line description.
    prefix : str
        The CasADi functions' prefix: ``<prefix>_ode``, ... (:data:`FUNCTIONS`), generated into ``<prefix>_casadi.c``.
    functions : tuple of casadi.Function
        The model's functions in the order of :data:`FUNCTIONS`.
    parameters : type
        The parameter dataclass (its field order is the CasADi parameter vector's).
    states : mapping
        State name -> (unit, description), in the state vector's order.
    derivative_units : mapping
        State name -> unit of its time derivative.
    outputs : mapping
        Output name -> (unit, description), in the order of ``<prefix>_outputs``.
    event_indicators, regime : sequence of str
        The event indicators' names and the discrete state's entries (Model Exchange).
    pulse : str
        The name stem of the rectangular pulse's parameters (``poke``: ``poke_magnitude``, ...): its edges are time events.
    state_ranges : mapping
        State name -> (min, max) where a state has a range.
    """

    identifier: str
    description: str
    prefix: str
    functions: tuple[ca.Function, ...]
    parameters: type
    states: Mapping[str, tuple[str, str]]
    derivative_units: Mapping[str, str]
    outputs: Mapping[str, tuple[str, str]]
    event_indicators: Sequence[str]
    regime: Sequence[str]
    pulse: str
    state_ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    constraints: Sequence[tuple[str, str]] = ()
    documentation: str = ""

    def __post_init__(self) -> None:
        expected = [f"{self.prefix}_{name}" for name in FUNCTIONS]
        if [f.name() for f in self.functions] != expected:
            raise ValueError(f"{self.identifier}: functions {[f.name() for f in self.functions]}, expected {expected}")

    def symbols(self) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
        """``state, V, p, t, regime`` of the sizes the functions take."""
        regime_function = self.functions[FUNCTIONS.index("ode_regime")]
        return (ca.SX.sym("state", len(self.states)), ca.SX.sym("V"), ca.SX.sym("p", len(self.parameters.names())),
                ca.SX.sym("t"), ca.SX.sym("regime", regime_function.size1_in(4)))

    def structure(self) -> tuple[dict[str, dict[str, str]], dict[str, dict[str, str]]]:
        """The dependencies (at communication points / in continuous time, and at initialization) from the CasADi
        functions' Jacobian structure: the outputs from ``<prefix>_outputs``, the derivatives from both the
        Co-Simulation law (``<prefix>_ode``, switches decided from the state) and Model Exchange's
        (``<prefix>_ode_regime``, switches frozen between events)."""
        ode, outputs, _, ode_regime, _, _ = self.functions
        state, V, pvec, t, regime = self.symbols()
        measured = outputs(state, V, pvec, t)
        return state_space_structure(
            state, {"V": V}, {name: pvec[k] for k, name in enumerate(self.parameters.names())}, list(self.states),
            {name: measured[k] for k, name in enumerate(self.outputs)},
            laws=(ode(state, V, pvec, t), ode_regime(state, V, pvec, t, regime)),
        )

    def spec(self) -> ModelSpec:
        """The FMU's :class:`~pendulab.fmu.description.ModelSpec` (FMI 2.0 Model Exchange and Co-Simulation)."""
        states = [
            Variable(s, "Real", "output", start=0.0, initial="exact", unit=unit, description=text,
                     min=self.state_ranges.get(s, (None, None))[0], max=self.state_ranges.get(s, (None, None))[1])
            for s, (unit, text) in self.states.items()
        ]
        derivatives = [
            Variable(f"der({s})", "Real", "local", unit=self.derivative_units[s], derivative_of=s, c_name=f"der_{s}",
                     description=f"Time derivative of {s}")
            for s in self.states
        ]
        # The outputs follow the input, consecutive in the order of <prefix>_outputs (state_space.c copies them).
        signals = [Variable("V", "Real", "input", start=0.0, unit="V", description="Voltage command to the amplifier")]
        signals += [Variable(name, "Real", "output", unit=unit, description=text) for name, (unit, text) in self.outputs.items()]
        names = self.parameters.names()
        structure, initial_structure = self.structure()
        with tempfile.TemporaryDirectory() as tmp:
            # The generated equations; any change to the model changes the text and so the GUID.
            stem = f"{self.prefix}_casadi"
            source = generate_c(self.functions, Path(tmp), stem)
            generated = {source.name: source.read_text(), f"{stem}.h": source.with_suffix(".h").read_text()}
        first_state, first_output = next(iter(self.states)), next(iter(self.outputs))
        return ModelSpec(
            identifier=self.identifier,
            description=self.description,
            variables=states + derivatives + signals + parameter_variables(self.parameters),
            states=list(self.states),
            sources=[SOURCE, f"{stem}.c"],
            event_indicators=len(self.event_indicators),
            event_indicator_names=self.event_indicators,
            generated=generated,
            dependencies=structure,
            initial_dependencies=initial_structure,
            constraints=self.constraints,
            documentation=self.documentation,
            defines={
                "CASADI_PREFIX": self.prefix,
                "CASADI_HEADER": f'"{stem}.h"',
                "VR_FIRST_STATE": f"VR_{first_state}",
                "VR_FIRST_DERIVATIVE": f"VR_der_{first_state}",
                "VR_FIRST_OUTPUT": f"VR_{first_output}",
                "N_OUTPUTS": str(len(self.outputs)),
                "VR_FIRST_PARAMETER": f"VR_{names[0]}",
                "N_PARAMETERS": str(len(names)),
                "VR_PULSE_MAGNITUDE": f"VR_{self.pulse}_magnitude",
                "VR_PULSE_DURATION": f"VR_{self.pulse}_duration",
                "VR_PULSE_START": f"VR_{self.pulse}_start",
                "MAX_SUBSTEP": repr(MAX_SUBSTEP),
                "N_REGIME": str(len(self.regime)),
                "CASADI_WORK_DOUBLES": str(max(1, *(f.sz_w() for f in self.functions))),
                "CASADI_WORK_INTS": str(max(1, *(f.sz_iw() for f in self.functions))),
            },
        )
