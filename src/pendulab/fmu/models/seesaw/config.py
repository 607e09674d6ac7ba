"""Seesaw FMU: variables (from :class:`SeesawParameters`) and C code generated from the CasADi model.

A Co-Simulation FMU (fixed RK4 sub-steps of at most 0.1 ms, as the plant's Co-Simulation); its equations
are :func:`pendulab.model.seesaw.seesaw_equations`, never written here.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import casadi as ca

from pendulab.fmu.description import ModelSpec, Variable, parameter_variables
from pendulab.fmu.structure import state_space_structure
from pendulab.model.plant import MAX_SUBSTEP
from pendulab.model.seesaw import OUTPUTS, STATES, SeesawModel, SeesawParameters

_STATE_TEXT = {
    "x": ("m", "Cart position along the track (0 at its centre)"),
    "xdot": ("m/s", "Cart velocity along the track"),
    "theta": ("rad", "Seesaw tilt from level (positive counter-clockwise facing the cart: the +x end up)"),
    "thetadot": ("rad/s", "Seesaw tilt rate"),
}


def model_structure(model: SeesawModel) -> tuple[dict[str, dict[str, str]], dict[str, dict[str, str]]]:
    """The outputs' dependencies from the CasADi model's Jacobian structure (``seesaw_outputs``): on the voltage
    at communication points (V_applied, F_friction), on states, V and parameters at initialization."""
    state, V, t = ca.SX.sym("state", len(STATES)), ca.SX.sym("V"), ca.SX.sym("t")
    pvec = ca.SX.sym("p", len(SeesawParameters.names()))
    measured = model.outputs(state, V, pvec, t)
    structure, initial = state_space_structure(state, {"V": V}, {n: pvec[k] for k, n in enumerate(SeesawParameters.names())},
                                               STATES, {name: measured[k] for k, name in enumerate(OUTPUTS)})
    # Co-Simulation only: the states are the FMU's own, not knowns at a communication point (only V is).
    return {u: {k: kind for k, kind in row.items() if k == "V"} for u, row in structure.items()}, initial


def spec() -> ModelSpec:
    states = [
        Variable(s, "Real", "output", start=0.0, initial="exact", unit=_STATE_TEXT[s][0], description=_STATE_TEXT[s][1])
        for s in STATES
    ]
    signals = [
        Variable("V", "Real", "input", start=0.0, unit="V", description="Voltage command to the amplifier"),
        Variable("theta_measured", "Real", "output", unit="rad", description="Tilt as the pivot encoder reads it (quantized by q_theta)"),
        Variable("x_measured", "Real", "output", unit="m", description="Cart position as the encoder reads it (quantized by q_x)"),
        Variable("V_applied", "Real", "output", unit="V", description="Voltage after the amplifier saturation"),
        Variable("F_friction", "Real", "output", unit="N", description="Stick-slip friction force on the cart"),
    ]
    parameters = parameter_variables(SeesawParameters)
    with tempfile.TemporaryDirectory() as tmp:
        model = SeesawModel()
        c_file = model.generate_c(Path(tmp))
        generated = {"seesaw_casadi.c": c_file.read_text(), "seesaw_casadi.h": c_file.with_suffix(".h").read_text()}
        functions = (model.outputs, model.rk4)
        work_doubles = max(f.sz_w() for f in functions)
        work_ints = max(f.sz_iw() for f in functions)
    names = SeesawParameters.names()
    structure, initial_structure = model_structure(model)
    return ModelSpec(
        identifier="Seesaw",
        description="IP02 cart on Quanser's SEESAW-E: DC motor, stick-slip friction, encoder quantization, track and tilt end stops, tap",
        variables=states + signals + parameters,
        sources=["model.c", "seesaw_casadi.c"],
        generated=generated,
        dependencies=structure,
        initial_dependencies=initial_structure,
        constraints=(("abs(x) <= track_half_length", "the cart starts between the track's end stops"),
                     ("abs(theta) <= theta_stop", "the seesaw starts between its tilt end stops")),
        documentation=__doc__.split("\n\n", 1)[1].replace("\n", " ").join(("<h2>Model</h2><p>", "</p>")),
        defines={
            "VR_FIRST_PARAMETER": f"VR_{names[0]}",
            "N_PARAMETERS": str(len(names)),
            "N_SEESAW_STATES": str(len(STATES)),
            "MAX_SUBSTEP": repr(MAX_SUBSTEP),
            "SEESAW_WORK_DOUBLES": str(max(1, work_doubles)),
            "SEESAW_WORK_INTS": str(max(1, work_ints)),
        },
    )
