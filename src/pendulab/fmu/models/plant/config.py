"""Plant FMU: variables (from :class:`PlantParameters`) and C code generated from the CasADi model."""

from __future__ import annotations

import tempfile
from pathlib import Path

import casadi as ca

from pendulab.fmu.description import ModelSpec, Variable, parameter_variables
from pendulab.fmu.models.plant.documentation import documentation
from pendulab.fmu.structure import state_space_structure
from pendulab.model.parameters import CONSTRAINTS, PlantParameters
from pendulab.model.plant import EVENT_INDICATORS, MAX_SUBSTEP, OUTPUTS, REGIME, STATES, PlantModel

_STATE_TEXT = {
    "x": ("m", "Cart position (positive to the right, 0 at track centre)"),
    "xdot": ("m/s", "Cart velocity"),
    "alpha": ("rad", "Pendulum angle from upright (positive counter-clockwise)"),
    "alphadot": ("rad/s", "Pendulum angular velocity"),
}
_DERIVATIVE_UNIT = {"x": "m/s", "xdot": "m/s2", "alpha": "rad/s", "alphadot": "rad/s2"}


#: The cart never leaves the longest track the parameter table allows (its end stops hold it).
_TRACK_MAX = PlantParameters.__dataclass_fields__["track_half_length"].metadata["max"]
_STATE_RANGE = {"x": (-_TRACK_MAX, _TRACK_MAX)}


def model_structure() -> tuple[dict[str, dict[str, str]], dict[str, dict[str, str]]]:
    """The plant's dependencies (at communication points / in continuous time, and at initialization) from the
    CasADi model's Jacobian structure: the outputs from ``plant_outputs``, the derivatives from both the
    Co-Simulation law (``plant_ode``, switches decided from the state) and Model Exchange's (``plant_ode_regime``,
    switches frozen between events)."""
    model = PlantModel()
    state, V, pvec, t, _ = model._symbols()
    regime = ca.SX.sym("regime", len(REGIME))
    measured = model.outputs(state, V, pvec, t)
    return state_space_structure(
        state, {"V": V}, {name: pvec[k] for k, name in enumerate(PlantParameters.names())}, STATES,
        {name: measured[k] for k, name in enumerate(OUTPUTS)},
        laws=(model.ode(state, V, pvec, t), model.ode_regime(state, V, pvec, t, regime)),
    )


def spec() -> ModelSpec:
    states = [
        Variable(s, "Real", "output", start=0.0, initial="exact", unit=_STATE_TEXT[s][0], description=_STATE_TEXT[s][1],
                 min=_STATE_RANGE.get(s, (None, None))[0], max=_STATE_RANGE.get(s, (None, None))[1])
        for s in STATES
    ]
    derivatives = [
        Variable(f"der({s})", "Real", "local", unit=_DERIVATIVE_UNIT[s], derivative_of=s, c_name=f"der_{s}",
                 description=f"Time derivative of {s}")
        for s in STATES
    ]
    signals = [
        Variable("V", "Real", "input", start=0.0, unit="V", description="Voltage command to the amplifier"),
        Variable("alpha_measured", "Real", "output", unit="rad", description="Angle as the encoder reads it (quantized by q_alpha)"),
        Variable("x_measured", "Real", "output", unit="m", description="Cart position as the encoder reads it (quantized by q_x)"),
        Variable("V_applied", "Real", "output", unit="V", description="Voltage after the amplifier saturation"),
        Variable("F_friction", "Real", "output", unit="N", description="Stick-slip friction force on the cart"),
    ]
    parameters = parameter_variables(PlantParameters)
    structure, initial_structure = model_structure()
    # The generated equations; any change to the model changes the text and so the GUID.
    with tempfile.TemporaryDirectory() as tmp:
        model = PlantModel()
        c_file = model.generate_c(Path(tmp))
        generated = {"plant_casadi.c": c_file.read_text(), "plant_casadi.h": c_file.with_suffix(".h").read_text()}
        functions = (model.ode, model.outputs, model.rk4, model.ode_regime, model.indicators, model.event_update)
        work_doubles = max(f.sz_w() for f in functions)
        work_ints = max(f.sz_iw() for f in functions)
    names = PlantParameters.names()
    return ModelSpec(
        identifier="Plant",
        description="Cart and inverted pendulum (Quanser IP02 style): DC motor, stick-slip friction, encoder quantization, track end stops, poke",
        variables=states + derivatives + signals + parameters,
        states=STATES,
        sources=["model.c", "plant_casadi.c"],
        event_indicators=len(EVENT_INDICATORS),
        event_indicator_names=EVENT_INDICATORS,
        generated=generated,
        dependencies=structure,
        initial_dependencies=initial_structure,
        # The start state lies inside the track (each variable's own range is checked when it is set).
        constraints=(*CONSTRAINTS, ("abs(x) <= track_half_length", "the cart starts between the end stops")),
        documentation=documentation(),
        defines={
            "VR_FIRST_PARAMETER": f"VR_{names[0]}",
            "N_PARAMETERS": str(len(names)),
            "MAX_SUBSTEP": repr(MAX_SUBSTEP),
            "N_REGIME": str(len(REGIME)),
            "PLANT_WORK_DOUBLES": str(max(1, work_doubles)),
            "PLANT_WORK_INTS": str(max(1, work_ints)),
        },
    )
