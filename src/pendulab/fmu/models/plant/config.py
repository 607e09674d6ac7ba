"""Plant FMU: variables (from :class:`PlantParameters`) and C code generated from the CasADi model
(:mod:`pendulab.fmu.state_space` builds it; ``fmu/c/state_space.c`` steps it)."""

from __future__ import annotations

from pendulab.fmu.description import ModelSpec
from pendulab.fmu.models.plant.documentation import documentation
from pendulab.fmu.state_space import StateSpaceFmu
from pendulab.model.parameters import CONSTRAINTS, PlantParameters
from pendulab.model.plant import EVENT_INDICATORS, REGIME, PlantModel

_STATE_TEXT = {
    "x": ("m", "Cart position (positive to the right, 0 at track centre)"),
    "xdot": ("m/s", "Cart velocity"),
    "alpha": ("rad", "Pendulum angle from upright (positive counter-clockwise)"),
    "alphadot": ("rad/s", "Pendulum angular velocity"),
}
_DERIVATIVE_UNIT = {"x": "m/s", "xdot": "m/s2", "alpha": "rad/s", "alphadot": "rad/s2"}
_OUTPUT_TEXT = {
    "alpha_measured": ("rad", "Angle as the encoder reads it (quantized by q_alpha)"),
    "x_measured": ("m", "Cart position as the encoder reads it (quantized by q_x)"),
    "V_applied": ("V", "Voltage after the amplifier saturation"),
    "F_friction": ("N", "Stick-slip friction force on the cart"),
}
#: The cart never leaves the longest track the parameter table allows (its end stops hold it).
_TRACK_MAX = PlantParameters.__dataclass_fields__["track_half_length"].metadata["max"]


def fmu() -> StateSpaceFmu:
    return StateSpaceFmu(
        identifier="Plant",
        description="Cart and inverted pendulum (Quanser IP02 style): DC motor, stick-slip friction, encoder quantization, track end stops, poke",
        prefix="plant",
        functions=PlantModel().functions,
        parameters=PlantParameters,
        states=_STATE_TEXT,
        derivative_units=_DERIVATIVE_UNIT,
        outputs=_OUTPUT_TEXT,
        event_indicators=EVENT_INDICATORS,
        regime=REGIME,
        pulse="poke",
        state_ranges={"x": (-_TRACK_MAX, _TRACK_MAX)},
        # The start state lies inside the track (each variable's own range is checked when it is set).
        constraints=(*CONSTRAINTS, ("abs(x) <= track_half_length", "the cart starts between the end stops")),
        documentation=documentation(),
    )


def spec() -> ModelSpec:
    return fmu().spec()
