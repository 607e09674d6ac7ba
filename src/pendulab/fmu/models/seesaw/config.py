"""Seesaw FMU: variables (from :class:`SeesawParameters`) and C code generated from the CasADi model.

FMI 2.0 Model Exchange and Co-Simulation in one FMU, as the plant's (:mod:`pendulab.fmu.state_space` builds both;
``fmu/c/state_space.c`` steps them). Co-Simulation: fixed RK4 sub-steps of at most 0.1 ms, the switches decided at
every evaluation. Model Exchange: the switches (friction regime, current-limit branch, the track's and the tilt's
end stops) frozen between events, located by event indicators; the tap's edges are time events. The equations
are :func:`pendulab.model.seesaw.seesaw_equations`, never written here.
"""

from __future__ import annotations

from pendulab.fmu.description import ModelSpec
from pendulab.fmu.state_space import StateSpaceFmu
from pendulab.model.seesaw import EVENT_INDICATORS, REGIME, SeesawModel, SeesawParameters

_STATE_TEXT = {
    "x": ("m", "Cart position along the track (0 at its centre)"),
    "xdot": ("m/s", "Cart velocity along the track"),
    "theta": ("rad", "Seesaw tilt from level (positive counter-clockwise facing the cart: the +x end up)"),
    "thetadot": ("rad/s", "Seesaw tilt rate"),
}
_DERIVATIVE_UNIT = {"x": "m/s", "xdot": "m/s2", "theta": "rad/s", "thetadot": "rad/s2"}
_OUTPUT_TEXT = {
    "theta_measured": ("rad", "Tilt as the pivot encoder reads it (quantized by q_theta)"),
    "x_measured": ("m", "Cart position as the encoder reads it (quantized by q_x)"),
    "V_applied": ("V", "Voltage after the amplifier saturation"),
    "F_friction": ("N", "Stick-slip friction force on the cart"),
}
_FIELDS = SeesawParameters.__dataclass_fields__
#: The end stops hold the cart and the seesaw within the widest ranges the parameter table allows.
_STATE_RANGE = {"x": (-_FIELDS["track_half_length"].metadata["max"], _FIELDS["track_half_length"].metadata["max"]),
                "theta": (-_FIELDS["theta_stop"].metadata["max"], _FIELDS["theta_stop"].metadata["max"])}


def fmu() -> StateSpaceFmu:
    return StateSpaceFmu(
        identifier="Seesaw",
        description="IP02 cart on Quanser's SEESAW-E: DC motor, stick-slip friction, encoder quantization, track and tilt end stops, tap",
        prefix="seesaw",
        functions=SeesawModel().functions,
        parameters=SeesawParameters,
        states=_STATE_TEXT,
        derivative_units=_DERIVATIVE_UNIT,
        outputs=_OUTPUT_TEXT,
        event_indicators=EVENT_INDICATORS,
        regime=REGIME,
        pulse="tap",
        state_ranges=_STATE_RANGE,
        constraints=(("abs(x) <= track_half_length", "the cart starts between the track's end stops"),
                     ("abs(theta) <= theta_stop", "the seesaw starts between its tilt end stops")),
        documentation="<h2>Model</h2><p>" + " ".join(__doc__.split("\n\n", 1)[1].split()) + "</p>",
    )


def spec() -> ModelSpec:
    return fmu().spec()
