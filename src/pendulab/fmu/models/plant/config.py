"""Plant FMU: variables (from :class:`PlantParameters`) and C code generated from the CasADi model."""

from __future__ import annotations

import tempfile
from pathlib import Path

from pendulab.fmu.description import ModelSpec, Variable
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import EVENT_INDICATORS, MAX_SUBSTEP, REGIME, STATES, PlantModel

_STATE_TEXT = {
    "x": ("m", "Cart position (positive to the right, 0 at track centre)"),
    "xdot": ("m/s", "Cart velocity"),
    "alpha": ("rad", "Pendulum angle from upright (positive counter-clockwise)"),
    "alphadot": ("rad/s", "Pendulum angular velocity"),
}
_DERIVATIVE_UNIT = {"x": "m/s", "xdot": "m/s2", "alpha": "rad/s", "alphadot": "rad/s2"}


def spec() -> ModelSpec:
    states = [
        Variable(s, "Real", "output", start=0.0, initial="exact", unit=_STATE_TEXT[s][0], description=_STATE_TEXT[s][1])
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
    parameters = [
        Variable(name, "Real", "parameter", start=float(default), unit=unit, description=text, initial="exact")
        for name, default, unit, text in PlantParameters.describe()
    ]
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
        defines={
            "VR_FIRST_PARAMETER": f"VR_{names[0]}",
            "N_PARAMETERS": str(len(names)),
            "MAX_SUBSTEP": repr(MAX_SUBSTEP),
            "N_REGIME": str(len(REGIME)),
            "PLANT_WORK_DOUBLES": str(max(1, work_doubles)),
            "PLANT_WORK_INTS": str(max(1, work_ints)),
            "PARAMETER_NAMES": "((const char *[]){" + ", ".join(f'"{n}"' for n in names) + "})",
        },
    )
