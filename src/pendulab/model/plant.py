"""The one symbolic model of the cart-pendulum plant, in CasADi.

Everything that needs the plant's equations takes them from here: the plant FMU's C code (generated
from :attr:`PlantModel.functions`), the linearization (:mod:`pendulab.model.linear`), the Python
reference integration used by the tests, and the least-squares calibration fit.

States ``[x, xdot, alpha, alphadot]``, input ``V`` (volts), parameters in the order of
:class:`~pendulab.model.parameters.PlantParameters`, time ``t`` (for the poke).

Examples
--------
>>> import numpy as np
>>> from pendulab.model.plant import PlantModel
>>> from pendulab.model.parameters import PlantParameters
>>> model = PlantModel()
>>> p = PlantParameters.preset("long")
>>> xdot = model.ode([0, 0, 0.01, 0], 0.0, p.as_vector(), 0.0)
>>> float(xdot[3]) > 0       # leaning pendulum falls further
True
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Sequence

import casadi as ca
import numpy as np

from pendulab.model.parameters import PlantParameters

STATES = ("x", "xdot", "alpha", "alphadot")
#: Outputs of :attr:`PlantModel.outputs`, in order (the plant FMU's outputs beside the states).
OUTPUTS = ("alpha_measured", "x_measured", "V_applied", "F_friction")
#: Largest RK4 sub-step inside one communication step (SPEC §6).
MAX_SUBSTEP = 1e-4


def quantize(value: ca.SX, step: ca.SX) -> ca.SX:
    """Encoder reading: ``value`` rounded half away from zero to a multiple of ``step`` (0 = off)."""
    safe_step = ca.if_else(step > 0, step, 1.0)
    counts = ca.sign(value) * ca.floor(ca.fabs(value) / safe_step + 0.5)
    return ca.if_else(step > 0, counts * safe_step, value)


def _smooth_step(z: ca.SX, width: ca.SX) -> ca.SX:
    """A differentiable stand-in for ``z > 0`` (for least-squares fitting only)."""
    return 0.5 * (1 + ca.tanh(z / width))


def poke_acceleration(p: dict[str, ca.SX], t: ca.SX) -> ca.SX:
    """The poke: a rectangular pulse of angular acceleration."""
    poke_on = ca.logic_and(t >= p["poke_start"], t < p["poke_start"] + p["poke_duration"])
    return ca.if_else(poke_on, p["poke_magnitude"], 0.0)


def mean_poke_acceleration(p: dict[str, ca.SX], t: ca.SX, h: ca.SX) -> ca.SX:
    """The poke averaged over ``[t, t+h]``: a fixed-step integrator that uses it gets the pulse's
    impulse exactly, wherever its edges fall inside a step."""
    start, end = p["poke_start"], p["poke_start"] + p["poke_duration"]
    overlap = ca.fmax(0.0, ca.fmin(t + h, end) - ca.fmax(t, start))
    return p["poke_magnitude"] * overlap / h


#: Discrete state of the Model Exchange plant (each changes only at events), in order.
REGIME = ("friction", "current", "stop", "count_alpha", "count_x")
#: Friction regimes (``REGIME[0]``). The two sliding regimes hold the speed on a surface between stick and slip
#: (``|xdot| = v1``, or ``|F_motor| = F1``: through the back-EMF a speed too) or between slip and free
#: (``|xdot| = v2`` or ``|F_motor| = F2``) where both sides push the cart onto it: the Filippov solution that
#: Co-Simulation's fixed step approximates by chattering.
FREE, SLIP, STICK, SLIDE_V1, SLIDE_V2 = 0.0, 1.0, 2.0, 3.0, 4.0
#: How close ``|xdot|`` must be to v1 or v2 for an event to count as on that surface (m/s).
SURFACE_TOLERANCE = 1e-9
#: How close ``|F_motor|`` must be to F1 or F2 for an event to count as on that surface (N; the motor's force
#: changes by about 8 N per m/s of the IP02's speed).
FORCE_TOLERANCE = 1e-8
#: The event indicators of the cart's drive (friction law, current limit, voltage saturation), in order: every
#: cart model (the plant, the seesaw) has them, then two per end stop (:class:`EndStop`).
DRIVE_INDICATORS = (
    "stick_speed", "stick_force", "slip_speed", "slip_force",
    "current_upper", "current_lower", "voltage_upper", "voltage_lower",
)


@dataclass(frozen=True)
class EndStop:
    """An end stop of one coordinate of a cart model, as Model Exchange's discrete state sees it.

    Attributes
    ----------
    name : str
        Its event indicators are ``<name>_upper`` and ``<name>_lower``.
    position : int
        Index of the coordinate in the state; its speed is the next state.
    limit : str
        The parameter that places the stops at ``+/- p[limit]``.
    slot : int
        Its entry in the regime vector: +1 held at the upper stop, -1 at the lower, 0 free.
    acceleration : str
        The signal of the equations that is the coordinate's acceleration were the stop not holding it.
    """

    name: str
    position: int
    limit: str
    slot: int
    acceleration: str

    @property
    def indicators(self) -> tuple[str, str]:
        return f"{self.name}_upper", f"{self.name}_lower"

    def holds(self, state: ca.SX, p: dict[str, ca.SX], acceleration: ca.SX, regime: ca.SX | None) -> ca.SX:
        """Whether the stop holds its coordinate: at the stop and pushed into it by ``acceleration`` (decided from
        the state: Co-Simulation's law), or as the ``regime`` froze it (Model Exchange)."""
        if regime is not None:
            return ca.fabs(regime[self.slot]) > 0.5
        q, speed, limit = state[self.position], state[self.position + 1], p[self.limit]
        return ca.logic_or(
            ca.logic_and(ca.logic_and(q >= limit, speed >= 0), acceleration > 0),
            ca.logic_and(ca.logic_and(q <= -limit, speed <= 0), acceleration < 0),
        )


#: The cart at the ends of its track.
TRACK_STOP = EndStop("stop", 0, "track_half_length", 2, "xddot_free")
#: The event indicators (zero crossings) of the Model Exchange plant, in order.
EVENT_INDICATORS = (*DRIVE_INDICATORS, *TRACK_STOP.indicators)
# The encoder steps are not event indicators: they switch no term of the right-hand side, and a CVode
# restart at every count (thousands per swing) cost more accuracy than it gave (1e-4 rad/s at rtol 1e-8).


def _amplifier(V: ca.SX, xdot: ca.SX, p: dict[str, ca.SX], current_mode: ca.SX | None) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """Voltage saturation, then the optional current limit on (V - back-EMF)/Rm.

    ``current_mode`` (-1, 0, +1) freezes the limit's branch (Model Exchange between events); None decides
    it from the current itself. Returns ``V_applied, raw current, current, F_motor``.
    """
    V_applied = ca.fmin(ca.fmax(V, -p["V_max"]), p["V_max"])
    omega_m = p["Kg"] * xdot / p["r_mp"]
    raw = (V_applied - p["Km"] * omega_m) / p["Rm"]
    if current_mode is None:
        current = ca.if_else(p["I_max"] > 0, ca.fmin(ca.fmax(raw, -p["I_max"]), p["I_max"]), raw)
    else:
        current = ca.if_else(current_mode > 0.5, p["I_max"], ca.if_else(current_mode < -0.5, -p["I_max"], raw))
    F_motor = p["force_gain"] * p["eta_g"] * p["Kg"] * p["eta_m"] * p["Kt"] * current / p["r_mp"]
    return V_applied, raw, current, F_motor


def _current_mode(raw: ca.SX, p: dict[str, ca.SX]) -> ca.SX:
    """Branch of the current limit the law picks: +1 above I_max, -1 below -I_max, else 0."""
    limited = p["I_max"] > 0
    return ca.if_else(ca.logic_and(limited, raw > p["I_max"]), 1.0, ca.if_else(ca.logic_and(limited, raw < -p["I_max"]), -1.0, 0.0))


def _friction_regime(xdot: ca.SX, F_motor: ca.SX, p: dict[str, ca.SX]) -> ca.SX:
    """The lab's stick-slip law: stick below v1 and F1, strong viscous slip below v2 and F2, else free."""
    sticks = ca.logic_and(ca.fabs(xdot) < p["v1"], ca.fabs(F_motor) < p["F1"])
    slips = ca.logic_and(ca.fabs(xdot) < p["v2"], ca.fabs(F_motor) < p["F2"])
    return ca.if_else(sticks, STICK, ca.if_else(slips, SLIP, FREE))


def friction_force(friction: ca.SX, F_motor: ca.SX, xdot: ca.SX, p: dict[str, ca.SX]) -> ca.SX:
    """The stick-slip law's force in a given regime (stick, slip or free; a sliding regime is the model's F_hold)."""
    return ca.if_else(friction > 1.5, -F_motor, ca.if_else(friction > 0.5, -p["B"] * xdot, 0.0))


def plant_equations(
    state: ca.SX,
    V: ca.SX,
    p: dict[str, ca.SX],
    t: ca.SX,
    *,
    smooth_friction: bool = False,
    poke: ca.SX | None = None,
    regime: ca.SX | None = None,
) -> tuple[ca.SX, dict[str, ca.SX]]:
    """The right-hand side of SPEC §2 and the intermediate signals.

    Parameters
    ----------
    state : SX (4,)
        ``[x, xdot, alpha, alphadot]``.
    V : SX
        Voltage command before the amplifier.
    p : dict of SX
        Parameters by name.
    t : SX
        Time, for the poke.
    smooth_friction : bool
        Replace the stick-slip switches by steep sigmoids so that the model is differentiable.
    poke : SX, optional
        The poke's angular acceleration; default :func:`poke_acceleration` at ``t``.
    regime : SX (5,), optional
        The discrete state of :data:`REGIME`: friction regime, current-limit branch and end stop held
        fixed (Model Exchange between events, where the right-hand side must be smooth). None: the
        switches are decided at every evaluation from the state (Co-Simulation's fixed-step law).

    Returns
    -------
    derivative : SX (4,)
    signals : dict
        ``V_applied``, ``current``, ``current_raw``, ``F_motor``, ``F_friction``, ``xddot_free`` (the
        cart's acceleration if no end stop held it) and, with the stick-slip switches, ``F_hold`` (the
        friction force that would keep the speed constant).
    """
    xdot, alpha, alphadot = state[1], state[2], state[3]

    V_applied, raw, current, F_motor = _amplifier(V, xdot, p, None if regime is None else regime[1])

    Mc = p["M_cart"] + p["eta_g"] * p["Kg"] ** 2 * p["Jm"] / p["r_mp"] ** 2
    Mp, lp, Ip = p["Mp"], p["lp"], p["Ip"]
    J = Ip + Mp * lp**2
    has_pendulum = J > 0
    gravity_torque = Mp * p["g"] * lp * ca.sin(alpha) - p["Bp"] * alphadot

    # Stick-slip friction (the lab's calibrated model).
    if smooth_friction:
        speed = ca.sqrt(xdot**2 + 1e-8)
        force = ca.sqrt(F_motor**2 + 1e-6)
        stick = _smooth_step(p["v1"] - speed, 2e-3) * _smooth_step(p["F1"] - force, 0.05)
        slip = _smooth_step(p["v2"] - speed, 5e-3) * _smooth_step(p["F2"] - force, 0.05)
        F_friction = -stick * F_motor - (1 - stick) * slip * p["B"] * xdot
        F_hold = None
    else:
        friction = _friction_regime(xdot, F_motor, p) if regime is None else regime[0]
        F_friction = friction_force(friction, F_motor, xdot, p)
        # The friction force that makes xddot = 0: a sliding regime holds the speed on its surface.
        base = F_motor - p["Beq"] * xdot - Mp * lp * ca.sin(alpha) * alphadot**2
        J_safe = ca.if_else(has_pendulum, J, 1.0)
        F_hold = ca.if_else(has_pendulum, -(base + Mp * lp * ca.cos(alpha) * gravity_torque / J_safe), -base)
        if regime is not None:  # the sliding regimes exist only as Model Exchange's discrete state
            F_friction = ca.if_else(friction > 2.5, F_hold, F_friction)
    F = F_motor + F_friction

    if poke is None:
        poke = poke_acceleration(p, t)

    cart_force = F - p["Beq"] * xdot - Mp * lp * ca.sin(alpha) * alphadot**2
    D = (Mc + Mp) * Ip + Mc * Mp * lp**2 + Mp**2 * lp**2 * ca.sin(alpha) ** 2
    # Without a pendulum (calibration ramps) D = 0: the cart alone obeys Mc xddot = F - Beq xdot.
    D_safe = ca.if_else(has_pendulum, D, 1.0)
    xddot = ca.if_else(
        has_pendulum,
        (J * cart_force + Mp * lp * ca.cos(alpha) * gravity_torque) / D_safe,
        (F - p["Beq"] * xdot) / Mc,
    )
    alphaddot = ca.if_else(
        has_pendulum,
        (Mp * lp * ca.cos(alpha) * cart_force + (Mc + Mp) * gravity_torque) / D_safe + poke,
        0.0,
    )
    # End stops: a cart at a stop and pushed into it is held there (the track takes the force); the
    # pendulum then swings about a fixed pivot. Co-Simulation's RK4 also projects the position back
    # onto the stop and kills the outward speed after each sub-step (plant_rk4).
    blocked = TRACK_STOP.holds(state, p, xddot, regime)
    alphaddot_held = ca.if_else(has_pendulum, gravity_torque / ca.if_else(has_pendulum, J, 1.0) + poke, 0.0)
    derivative = ca.vertcat(
        ca.if_else(blocked, 0.0, xdot),
        ca.if_else(blocked, 0.0, xddot),
        alphadot,
        ca.if_else(blocked, alphaddot_held, alphaddot),
    )
    signals = {
        "V_applied": V_applied, "current": current, "current_raw": raw, "F_motor": F_motor,
        "F_friction": F_friction, "xddot_free": xddot,
    }
    if F_hold is not None:
        signals["F_hold"] = F_hold
    return derivative, signals


def _encoder_count(value: ca.SX, step: ca.SX) -> ca.SX:
    safe_step = ca.if_else(step > 0, step, 1.0)
    return ca.if_else(step > 0, ca.sign(value) * ca.floor(ca.fabs(value) / safe_step + 0.5), 0.0)


def switches_at(
    state: ca.SX, V: ca.SX, p: dict[str, ca.SX], regime: ca.SX,
    signals: Callable[[ca.SX, ca.SX], dict[str, ca.SX]], stops: Sequence[EndStop],
) -> tuple[ca.SX, ca.SX, list[ca.SX], ca.SX]:
    """Event update of a cart model in Model Exchange: the switches the law picks at this point.

    The law is the one Co-Simulation evaluates at every step (the equations without a regime); a coordinate
    that reaches an end stop from inside stops dead on it. The cart's drive (friction law, current limit) is the
    same for every cart model; its mechanics come in through ``signals``.

    Parameters
    ----------
    state : SX
        The state; the cart's position and speed are its first two entries.
    regime : SX
        The discrete state: friction regime, current-limit branch, then each stop's slot, then the model's own.
    signals : callable
        ``signals(state, regime)``: the model's signals (``F_motor``, ``current_raw``, ``F_hold``, each stop's
        acceleration) with its switches frozen in ``regime``.
    stops : sequence of EndStop

    Returns
    -------
    friction, current_mode : SX
        The new regime's first two entries.
    stop_slots : list of SX
        Each stop's new slot (+1, -1, 0).
    state : SX
        The state after the event (changed only where a coordinate hits a stop).
    """
    new = [state[k] for k in range(state.numel())]
    for stop in stops:
        q, speed, limit, held = state[stop.position], state[stop.position + 1], p[stop.limit], regime[stop.slot]
        hit_upper = ca.logic_and(held == 0, ca.logic_and(q >= limit, speed >= 0))
        hit_lower = ca.logic_and(held == 0, ca.logic_and(q <= -limit, speed <= 0))
        new[stop.position] = ca.if_else(hit_upper, limit, ca.if_else(hit_lower, -limit, q))
        new[stop.position + 1] = ca.if_else(ca.logic_or(ca.logic_or(hit_upper, hit_lower), held != 0), 0.0, speed)
    new_state = ca.vertcat(*new)
    xdot_new = new[1]
    _, raw, _, _ = _amplifier(V, xdot_new, p, None)
    current_mode = _current_mode(raw, p)
    _, _, _, F_motor = _amplifier(V, xdot_new, p, current_mode)
    friction = _friction_regime(xdot_new, F_motor, p)

    def frozen(friction_value: ca.SX | float) -> ca.SX:
        # The regime with the given friction and this current branch; the stops as they were (a stop's slot
        # does not change its coordinate's free acceleration; the event iteration settles the rest).
        return ca.vertcat(friction_value, current_mode, regime[2:])

    def push(friction_value: float) -> ca.SX:
        # The cart's acceleration along its velocity under a given friction regime (> 0: speeding up).
        return ca.sign(xdot_new) * signals(new_state, frozen(friction_value))["xddot_free"]

    # On a speed surface the law's choice may be pushed straight back across it: pick the side whose
    # dynamics leave the surface into its own region, or slide on the surface if both push onto it.
    speed = ca.fabs(xdot_new)
    on_v1 = ca.logic_and(ca.fabs(speed - p["v1"]) < SURFACE_TOLERANCE, ca.logic_and(ca.fabs(F_motor) < p["F1"], ca.fabs(F_motor) < p["F2"]))
    on_v1 = ca.logic_and(on_v1, p["v1"] < p["v2"])
    on_v2 = ca.logic_and(ca.fabs(speed - p["v2"]) < SURFACE_TOLERANCE, ca.fabs(F_motor) < p["F2"])
    at_v1 = ca.if_else(push(STICK) < 0, STICK, ca.if_else(push(SLIP) > 0, SLIP, SLIDE_V1))
    at_v2 = ca.if_else(push(SLIP) < 0, SLIP, ca.if_else(push(FREE) > 0, FREE, SLIDE_V2))
    # The force surfaces: with the current unlimited, |F_motor| falls as the cart speeds up along it (back-EMF),
    # so the stick (slip) side is left into its own region by an acceleration along F_motor.
    unlimited = current_mode == 0

    def along_force(friction_value: float) -> ca.SX:
        return ca.sign(F_motor) * signals(new_state, frozen(friction_value))["xddot_free"]

    force = ca.fabs(F_motor)
    on_F1 = ca.logic_and(ca.logic_and(ca.fabs(force - p["F1"]) < FORCE_TOLERANCE, speed < p["v1"]),
                         ca.logic_and(ca.logic_and(force < p["F2"], p["F1"] > 0), unlimited))
    on_F2 = ca.logic_and(ca.logic_and(ca.fabs(force - p["F2"]) < FORCE_TOLERANCE, speed < p["v2"]),
                         ca.logic_and(ca.logic_and(p["F1"] < p["F2"], p["F2"] > 0), unlimited))
    at_F1 = ca.if_else(along_force(STICK) > 0, STICK, ca.if_else(along_force(SLIP) < 0, SLIP, SLIDE_V1))
    at_F2 = ca.if_else(along_force(SLIP) > 0, SLIP, ca.if_else(along_force(FREE) < 0, FREE, SLIDE_V2))
    friction = ca.if_else(on_v1, at_v1, ca.if_else(on_v2, at_v2, ca.if_else(on_F1, at_F1, ca.if_else(on_F2, at_F2, friction))))
    settled = signals(new_state, frozen(friction))
    slots = []
    for stop in stops:
        # At a stop the coordinate stays while the net force pushes it into the stop.
        q, limit, acceleration = new[stop.position], p[stop.limit], settled[stop.acceleration]
        at_upper = ca.logic_and(q >= limit, acceleration > 0)
        at_lower = ca.logic_and(q <= -limit, acceleration < 0)
        slots.append(ca.if_else(at_upper, 1.0, ca.if_else(at_lower, -1.0, 0.0)))
    return friction, current_mode, slots, new_state


def switch_indicators(state: ca.SX, p: dict[str, ca.SX], V: ca.SX, regime: ca.SX, signals: dict[str, ca.SX],
                      stops: Sequence[EndStop]) -> ca.SX:
    """The zero-crossing functions of a cart model: :data:`DRIVE_INDICATORS`, then each stop's two. Each changes
    sign where a switch of the right-hand side changes; a switch that is turned off by its parameter gives a
    constant. ``signals`` are the model's with its switches frozen in ``regime`` (see :func:`switches_at`)."""
    xdot = state[1]
    F_motor, raw = signals["F_motor"], signals["current_raw"]
    stick_on, slip_on, limit_on = p["F1"] > 0, p["F2"] > 0, p["I_max"] > 0
    friction, F_hold = regime[0], signals["F_hold"]
    # While sliding, the holding force must stay between the two sides' forces.
    slide_v1 = (F_hold + F_motor) * (-p["B"] * xdot - F_hold)
    slide_v2 = (F_hold + p["B"] * xdot) * (0.0 - F_hold)
    z = [
        ca.if_else(friction == SLIDE_V1, slide_v1, ca.if_else(stick_on, p["v1"] - ca.fabs(xdot), 1.0)),
        ca.if_else(stick_on, p["F1"] - ca.fabs(F_motor), -1.0),
        ca.if_else(friction == SLIDE_V2, slide_v2, ca.if_else(slip_on, p["v2"] - ca.fabs(xdot), 1.0)),
        ca.if_else(slip_on, p["F2"] - ca.fabs(F_motor), -1.0),
        ca.if_else(limit_on, p["I_max"] - raw, 1.0),
        ca.if_else(limit_on, p["I_max"] + raw, 1.0),
        p["V_max"] - V,
        p["V_max"] + V,
    ]
    for stop in stops:
        q, limit, held = state[stop.position], p[stop.limit], regime[stop.slot]
        # Free: distance to each stop. Held: how hard the coordinate is pressed into its stop.
        z += [ca.if_else(held == 0, limit - q, held * signals[stop.acceleration]), ca.if_else(held == 0, q + limit, 1.0)]
    return ca.vertcat(*z)


def regime_at(state: ca.SX, V: ca.SX, p: dict[str, ca.SX], t: ca.SX, regime: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Event update of the Model Exchange plant (:func:`switches_at` with the plant's mechanics and its track).

    Returns
    -------
    regime : SX (5,)
        The new :data:`REGIME`.
    state : SX (4,)
        The state after the event (changed only when the cart hits a stop).
    """
    friction, current_mode, (stop,), new_state = switches_at(
        state, V, p, regime, lambda s, r: plant_equations(s, V, p, t, regime=r)[1], (TRACK_STOP,))
    new_regime = ca.vertcat(
        friction, current_mode, stop, _encoder_count(state[2], p["q_alpha"]), _encoder_count(new_state[0], p["q_x"])
    )
    return new_regime, new_state


def event_indicators(state: ca.SX, V: ca.SX, p: dict[str, ca.SX], t: ca.SX, regime: ca.SX) -> ca.SX:
    """The zero-crossing functions of :data:`EVENT_INDICATORS` (:func:`switch_indicators` of the plant)."""
    return switch_indicators(state, p, V, regime, plant_equations(state, V, p, t, regime=regime)[1], (TRACK_STOP,))


@dataclass(frozen=True)
class PlantModel:
    """Numerical CasADi functions of the plant, built from :func:`plant_equations`.

    Attributes
    ----------
    ode : casadi.Function
        ``plant_ode(state[4], V, p[np], t) -> derivative[4]``
    outputs : casadi.Function
        ``plant_outputs(state[4], V, p[np], t) -> [alpha_measured, x_measured, V_applied, F_friction]``
    rk4 : casadi.Function
        ``plant_rk4(state[4], V, p[np], t, h) -> state after one classical RK4 step of length h``
    """

    smooth_friction: bool = False

    @property
    def n_parameters(self) -> int:
        return len(PlantParameters.names())

    def _symbols(self) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, dict[str, ca.SX]]:
        state = ca.SX.sym("state", 4)
        V = ca.SX.sym("V")
        pvec = ca.SX.sym("p", self.n_parameters)
        t = ca.SX.sym("t")
        p = {name: pvec[i] for i, name in enumerate(PlantParameters.names())}
        return state, V, pvec, t, p

    @property
    def ode(self) -> ca.Function:
        return _functions(self.smooth_friction)[0]

    @property
    def outputs(self) -> ca.Function:
        return _functions(self.smooth_friction)[1]

    @property
    def rk4(self) -> ca.Function:
        return _functions(self.smooth_friction)[2]

    @property
    def ode_regime(self) -> ca.Function:
        """``plant_ode_regime(state[4], V, p[np], t, regime[5]) -> derivative[4]``: the right-hand side
        with the switches frozen (Model Exchange between events)."""
        return _regime_functions()[0]

    @property
    def indicators(self) -> ca.Function:
        """``plant_indicators(state[4], V, p[np], t, regime[5]) -> z[10]`` (:data:`EVENT_INDICATORS`)."""
        return _regime_functions()[1]

    @property
    def event_update(self) -> ca.Function:
        """``plant_event(state[4], V, p[np], t, regime[5]) -> (regime[5], state[4])`` (:func:`regime_at`)."""
        return _regime_functions()[2]

    @property
    def functions(self) -> tuple[ca.Function, ...]:
        """Every function the plant FMU's C code is generated from (:mod:`pendulab.fmu.state_space`), in the
        order ``plant_ode``, ``plant_outputs``, ``plant_rk4``, ``plant_ode_regime``, ``plant_indicators``,
        ``plant_event``."""
        return (self.ode, self.outputs, self.rk4, self.ode_regime, self.indicators, self.event_update)

    def simulate(
        self,
        params: PlantParameters,
        V: Sequence[float] | np.ndarray,
        step: float = 1e-3,
        x0: Sequence[float] = (0.0, 0.0, 0.0, 0.0),
        substep: float = MAX_SUBSTEP,
        t0: float = 0.0,
    ) -> np.ndarray:
        """Reference integration: RK4 sub-steps of the CasADi right-hand side, voltage held per step.

        Parameters
        ----------
        V : array (n,)
            Voltage held during each communication step of length ``step``, the first from ``t0``.

        Returns
        -------
        array (n+1, 4)
            The states at ``t = 0, step, ..., n*step``.
        """
        V = np.asarray(V, dtype=float)
        n_sub = substeps(step, substep)
        h = step / n_sub
        # The mapped function integrates one communication step per call (fast in CasADi's VM).
        one_step = step_function(self.smooth_friction, n_sub)
        p = np.asarray(params.as_vector())
        out = np.empty((len(V) + 1, 4))
        out[0] = x0
        state = np.asarray(x0, dtype=float)
        for k, v in enumerate(V):
            state = np.asarray(one_step(state, v, p, t0 + k * step, h)).ravel()
            out[k + 1] = state
        return out


def substeps(step: float, max_substep: float = MAX_SUBSTEP) -> int:
    """Number of equal RK4 sub-steps so that none is longer than ``max_substep``.

    The same rule is compiled into the plant FMU.
    """
    return max(1, int(np.ceil(step / max_substep - 1e-9)))


@lru_cache(maxsize=None)
def _functions(smooth_friction: bool) -> tuple[ca.Function, ca.Function, ca.Function]:
    model = PlantModel.__new__(PlantModel)
    object.__setattr__(model, "smooth_friction", smooth_friction)
    state, V, pvec, t, p = model._symbols()
    derivative, signals = plant_equations(state, V, p, t, smooth_friction=smooth_friction)
    ode = ca.Function("plant_ode", [state, V, pvec, t], [derivative], ["state", "V", "p", "t"], ["derivative"])
    measured = ca.vertcat(
        quantize(state[2], p["q_alpha"]),
        quantize(state[0], p["q_x"]),
        signals["V_applied"],
        signals["F_friction"],
    )
    outputs = ca.Function("plant_outputs", [state, V, pvec, t], [measured], ["state", "V", "p", "t"], ["y"])
    h = ca.SX.sym("h")
    # RK4 with the poke averaged over the sub-step: the pulse's edges fall anywhere inside a
    # sub-step, and sampling them at the stage times would get its impulse wrong.
    poke = mean_poke_acceleration(p, t, h)

    def f(s: ca.SX) -> ca.SX:
        return plant_equations(s, V, p, t, smooth_friction=smooth_friction, poke=poke)[0]

    k1 = f(state)
    k2 = f(state + h / 2 * k1)
    k3 = f(state + h / 2 * k2)
    k4 = f(state + h * k3)
    stepped = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    # End stops: a sub-step that carries the cart past a stop ends on the stop, with no outward speed.
    L = p["track_half_length"]
    x_next, v_next = stepped[0], stepped[1]
    stepped = ca.vertcat(
        ca.fmin(ca.fmax(x_next, -L), L),
        ca.if_else(x_next >= L, ca.fmin(v_next, 0.0), ca.if_else(x_next <= -L, ca.fmax(v_next, 0.0), v_next)),
        stepped[2],
        stepped[3],
    )
    rk4 = ca.Function("plant_rk4", [state, V, pvec, t, h], [stepped], ["state", "V", "p", "t", "h"], ["next"])
    return ode, outputs, rk4


@lru_cache(maxsize=None)
def _regime_functions() -> tuple[ca.Function, ca.Function, ca.Function]:
    model = PlantModel()
    state, V, pvec, t, p = model._symbols()
    regime = ca.SX.sym("regime", len(REGIME))
    args, names = [state, V, pvec, t, regime], ["state", "V", "p", "t", "regime"]
    derivative = plant_equations(state, V, p, t, regime=regime)[0]
    ode = ca.Function("plant_ode_regime", args, [derivative], names, ["derivative"])
    z = event_indicators(state, V, p, t, regime)
    indicators = ca.Function("plant_indicators", args, [z], names, ["z"])
    new_regime, new_state = regime_at(state, V, p, t, regime)
    update = ca.Function("plant_event", args, [new_regime, new_state], names, ["regime_next", "state_next"])
    return ode, indicators, update


@lru_cache(maxsize=None)
def _regime_of_state() -> ca.Function:
    model = PlantModel()
    state, V, pvec, t, p = model._symbols()
    signals = plant_equations(state, V, p, t)[1]
    return ca.Function("plant_friction_regime", [state, V, pvec], [_friction_regime(state[1], signals["F_motor"], p)])


def friction_regimes(params: PlantParameters, states: np.ndarray, V: np.ndarray) -> np.ndarray:
    """The stick-slip law's regime (:data:`FREE`, :data:`SLIP` or :data:`STICK`) at each of ``states`` ``(n, 4)``
    under the voltages ``V`` ``(n,)``, as the plant decides it (the motor's force through the amplifier).

    Examples
    --------
    >>> p = PlantParameters.preset("none")                      # v1 0.005, v2 0.05 m/s
    >>> states = np.array([[0, 0, 0, 0], [0, 0.01, 0, 0], [0, 0.2, 0, 0]], dtype=float)
    >>> friction_regimes(p, states, np.zeros(3)).tolist() == [STICK, SLIP, FREE]
    True
    """
    states = np.atleast_2d(np.asarray(states, dtype=float))
    f = _regime_of_state().map(states.shape[0])
    return np.asarray(f(states.T, np.asarray(V, dtype=float)[None, :], np.asarray(params.as_vector(), dtype=float))).ravel()


@lru_cache(maxsize=None)
def step_function(smooth_friction: bool, n_sub: int) -> ca.Function:
    """``n_sub`` RK4 sub-steps of the plant as one CasADi function ``plant_step(state, V, p, t, h) -> state``.

    Parameters
    ----------
    smooth_friction : bool
        The smoothed stick-slip law (for fitting) instead of the true one.
    n_sub : int
        Number of RK4 sub-steps of length ``h`` (see :func:`substeps`).

    Examples
    --------
    >>> step = step_function(False, 2)
    >>> step.name(), step.n_in()
    ('plant_step', 5)
    """
    rk4 = _functions(smooth_friction)[2]
    state = ca.MX.sym("state", 4)
    V, t, h = ca.MX.sym("V"), ca.MX.sym("t"), ca.MX.sym("h")
    p = ca.MX.sym("p", len(PlantParameters.names()))
    s = state
    for i in range(n_sub):
        s = rk4(s, V, p, t + i * h, h)
    return ca.Function("plant_step", [state, V, p, t, h], [s])
