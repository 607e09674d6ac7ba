"""The seesaw: the IP02 cart on Quanser's SEESAW-E module, in the same CasADi model family as the pendulum.

The cart runs on a track that sits on a seesaw; the seesaw pivots and the cart, driven by the same motor
and amplifier, balances it. The motor, the amplifier's limits, the stick-slip friction law and the
encoders are the pendulum plant's own (:mod:`pendulab.model.plant`); only the mechanics differ.

Coordinates (SPEC §2): ``x`` along the track from its centre (m), ``theta`` the seesaw's tilt from level
(rad, positive counter-clockwise facing the cart: the +x end up). States ``[x, xdot, theta, thetadot]``.

Equations of motion (Lagrange; the cart a point mass ``mc`` at height ``D_T`` above the pivot, the
seesaw and track a rigid body of mass ``M_sw`` with its centre of gravity ``D_C`` above the pivot and
inertia ``J_sw`` about the pivot)::

    M(x) [xddot, thetaddot] = [F_net + mc x thetadot^2 - mc g sin(theta),
                               -2 mc x xdot thetadot - mc g (x cos(theta) - D_T sin(theta))
                               + M_sw g D_C sin(theta) - B_sw thetadot]
    M(x) = [[m_x, -mc D_T], [-mc D_T, J_sw + mc (x^2 + D_T^2)]]
    F_net = F_motor + F_friction - Beq xdot,   m_x = mc + rotor_inertia * eta_g Kg^2 Jm / r_mp^2

A tap (a rectangular pulse added to ``thetaddot``, like the pendulum's poke) is the disturbance. Quanser's
model (``SEESAW_ABCD_eqns.m``) neglects the rotor inertia: ``rotor_inertia = 0`` is the default, so that
its published matrices check ours; ``rotor_inertia = 1`` lumps it into the cart's inertia along the track.

Examples
--------
>>> from pendulab.model.seesaw import SeesawModel, SeesawParameters
>>> p = SeesawParameters()
>>> d = SeesawModel().ode([0.01, 0, 0, 0], 0.0, p.as_vector(), 0.0)
>>> float(d[3]) < 0        # the cart on the +x side tips the seesaw down on that side
True
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields
from functools import lru_cache
from typing import Any, Mapping, Sequence

import casadi as ca
import control
import numpy as np

from pendulab.errors import ParameterError
from pendulab.model.parameters import PlantParameters, _p, check_ranges
from pendulab.model.plant import (
    DRIVE_INDICATORS,
    MAX_SUBSTEP,
    TRACK_STOP,
    EndStop,
    _amplifier,
    _friction_regime,
    friction_force,
    mean_poke_acceleration,
    poke_acceleration,
    quantize,
    substeps,
    switch_indicators,
    switches_at,
)

STATES = ("x", "xdot", "theta", "thetadot")
#: Outputs of :attr:`SeesawModel.outputs`, in order.
OUTPUTS = ("theta_measured", "x_measured", "V_applied", "F_friction")
#: Seesaw tilt per encoder count: a 1024-line encoder read in quadrature (x4) behind a 3:1 gear
#: (``config_ssw.m``: ``KE_SW = 2*pi/(4*1024)``, ``Kgs = 3``).
SEESAW_COUNT = 2 * math.pi / 4096 / 3
#: The seesaw resting on the floor at its tilt stops.
TILT_STOP = EndStop("tilt_stop", 2, "theta_stop", 3, "thetaddot_free")
#: Discrete state of the Model Exchange seesaw (each changes only at events), in order: the plant's drive
#: (:data:`pendulab.model.plant.REGIME`'s friction and current branch), the track's stops, the tilt's stops.
REGIME = ("friction", "current", "stop", "tilt_stop")
#: The event indicators (zero crossings) of the Model Exchange seesaw, in order.
EVENT_INDICATORS = (*DRIVE_INDICATORS, *TRACK_STOP.indicators, *TILT_STOP.indicators)


def _cart_field(name: str) -> Any:
    """A field of the cart, motor, amplifier, friction or cart encoder, as the pendulum plant declares it."""
    f = PlantParameters.__dataclass_fields__[name]
    m = f.metadata
    return _p(f.default, m["unit"], m["description"], minimum=m["min"], maximum=m["max"], positive=m["positive"])


@dataclass(frozen=True)
class SeesawParameters:
    """Every parameter of the seesaw plant, in SI units.

    The cart, motor, amplifier, friction and cart-encoder fields are the pendulum plant's
    (:class:`~pendulab.model.parameters.PlantParameters`, same names, units and defaults: the IP02 without
    its extra weight). The seesaw's values come from Quanser's 2012 courseware (``config_ssw.m``).
    """

    M_cart: float = _cart_field("M_cart")
    Beq: float = _cart_field("Beq")
    Rm: float = _cart_field("Rm")
    Kt: float = _cart_field("Kt")
    Km: float = _cart_field("Km")
    Kg: float = _cart_field("Kg")
    eta_g: float = _cart_field("eta_g")
    eta_m: float = _cart_field("eta_m")
    Jm: float = _cart_field("Jm")
    r_mp: float = _cart_field("r_mp")
    force_gain: float = _cart_field("force_gain")
    g: float = _cart_field("g")
    V_max: float = _cart_field("V_max")
    I_max: float = _cart_field("I_max")
    F1: float = _cart_field("F1")
    v1: float = _cart_field("v1")
    F2: float = _cart_field("F2")
    v2: float = _cart_field("v2")
    B: float = _cart_field("B")
    q_x: float = _cart_field("q_x")
    track_half_length: float = _cart_field("track_half_length")
    rotor_inertia: float = _p(0.0, "1", "1 lumps the motor's rotor inertia into the cart along the track; 0 neglects it (Quanser's model)", 0, 1)
    # the seesaw (config_ssw.m)
    M_sw: float = _p(3.6, "kg", "Mass of the seesaw and track, without the cart", 0.01, 100)
    D_T: float = _p(0.125, "m", "Pivot to the track (the cart's centre of gravity)", 0, 5)
    D_C: float = _p(0.058, "m", "Pivot to the centre of gravity of seesaw and track, above the pivot", 0, 5)
    J_sw: float = _p(0.395, "kg.m2", "Inertia of the seesaw and track about the pivot", 1e-4, 100)
    B_sw: float = _p(0.0, "N.m.s/rad", "Viscous damping at the pivot", 0, 100)
    q_theta: float = _p(SEESAW_COUNT, "rad", "Tilt encoder step (0 = no quantization)", 0, 1)
    theta_stop: float = _p(
        math.radians(11.5), "rad", "Tilt end stops: the seesaw rests on the floor at +/- this tilt (above pi: no stops)", 1e-3, 10
    )
    # tap: a rectangular pulse added to the tilt's angular acceleration
    tap_magnitude: float = _p(3.3, "rad/s2", "Tap magnitude (3.3 for 0.1 s tilts the seesaw about 5 deg under Quanser's LQR)", -1e5, 1e5)
    tap_duration: float = _p(0.1, "s", "Tap duration", 0, 1e3)
    tap_start: float = _p(1.0, "s", "Tap start time", 0, 1e6)

    def __post_init__(self) -> None:
        check_ranges(self, "seesaw parameter")
        if self.rotor_inertia not in (0.0, 1.0):
            raise ParameterError(f"seesaw parameter rotor_inertia={self.rotor_inertia} must be 0 (neglected) or 1 (lumped)")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """Field names in their fixed order (the order of the CasADi parameter vector)."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def from_mapping(cls, values: Mapping[str, float]) -> "SeesawParameters":
        """Build from a mapping of field names; unknown names are an error."""
        unknown = sorted(set(values) - set(cls.names()))
        if unknown:
            raise ParameterError(f"unknown seesaw parameter {unknown[0]!r}; known ones are {', '.join(cls.names())}")
        return cls(**{k: float(v) for k, v in values.items()})

    def with_values(self, **values: float) -> "SeesawParameters":
        """A copy with some fields changed (validated like a new object)."""
        return type(self).from_mapping({**self.as_dict(), **values})

    def as_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    def as_vector(self) -> list[float]:
        return [getattr(self, n) for n in self.names()]

    def without_nonlinearities(self) -> "SeesawParameters":
        """Friction, quantization, current limit and tap off (the linearization's assumptions)."""
        return self.with_values(F1=0.0, F2=0.0, q_theta=0.0, q_x=0.0, I_max=0.0, tap_magnitude=0.0)


def _tap(p: dict[str, ca.SX]) -> dict[str, ca.SX]:
    # The tap is the poke's pulse on another axis: the poke's functions read these names.
    return {"poke_magnitude": p["tap_magnitude"], "poke_duration": p["tap_duration"], "poke_start": p["tap_start"]}


def seesaw_equations(
    state: ca.SX, V: ca.SX, p: dict[str, ca.SX], t: ca.SX, *, tap: ca.SX | None = None, regime: ca.SX | None = None
) -> tuple[ca.SX, dict[str, ca.SX]]:
    """The right-hand side of the seesaw and its intermediate signals (see the module's docstring).

    Parameters
    ----------
    state : SX (4,)
        ``[x, xdot, theta, thetadot]``.
    V : SX
        Voltage command before the amplifier.
    p : dict of SX
        Parameters by name (:class:`SeesawParameters`).
    t : SX
        Time, for the tap.
    tap : SX, optional
        The tap's angular acceleration; default the pulse at ``t``.
    regime : SX (4,), optional
        The discrete state of :data:`REGIME`: friction regime, current-limit branch, the track's and the tilt's
        stops held fixed (Model Exchange between events). None: the switches are decided at every evaluation from
        the state (Co-Simulation's fixed-step law).

    Returns
    -------
    derivative : SX (4,)
    signals : dict
        ``V_applied``, ``F_motor``, ``F_friction``, ``current_raw``, ``xddot_free`` and ``thetaddot_free`` (each
        coordinate's acceleration were its stop not holding it) and, with a regime, ``F_hold`` (the friction
        force that keeps the cart's speed constant).
    """
    x, xdot, theta, thetadot = state[0], state[1], state[2], state[3]
    V_applied, raw, _, F_motor = _amplifier(V, xdot, p, None if regime is None else regime[1])
    friction = _friction_regime(xdot, F_motor, p) if regime is None else regime[0]
    F_friction = friction_force(friction, F_motor, xdot, p)

    mc, Dt, g = p["M_cart"], p["D_T"], p["g"]
    m_x = mc + p["rotor_inertia"] * p["eta_g"] * p["Kg"] ** 2 * p["Jm"] / p["r_mp"] ** 2
    m_theta = p["J_sw"] + mc * (x**2 + Dt**2)
    rhs_theta = (
        -2 * mc * x * xdot * thetadot
        - mc * g * (x * ca.cos(theta) - Dt * ca.sin(theta))
        + p["M_sw"] * g * p["D_C"] * ca.sin(theta)
        - p["B_sw"] * thetadot
    )
    signals = {"V_applied": V_applied, "F_motor": F_motor, "current_raw": raw}
    if regime is not None:
        # The friction force that makes xddot = 0 (the tilt free or resting on its stop): a sliding regime holds
        # the cart's speed on its surface with it.
        tilt_held = TILT_STOP.holds(state, p, 0.0, regime)
        base = F_motor - p["Beq"] * xdot + mc * x * thetadot**2 - mc * g * ca.sin(theta)
        signals["F_hold"] = -(base + ca.if_else(tilt_held, 0.0, mc * Dt * rhs_theta / m_theta))
        F_friction = ca.if_else(friction > 2.5, signals["F_hold"], F_friction)
    F_net = F_motor + F_friction - p["Beq"] * xdot
    rhs_x = F_net + mc * x * thetadot**2 - mc * g * ca.sin(theta)
    det = m_x * m_theta - (mc * Dt) ** 2
    if tap is None:
        tap = poke_acceleration(_tap(p), t)
    xddot = (m_theta * rhs_x + mc * Dt * rhs_theta) / det
    thetaddot = (m_x * rhs_theta + mc * Dt * rhs_x) / det + tap

    # End stops. The cart at a track end stops dead there as on the pendulum's track; the seesaw at a
    # tilt stop rests on the floor, and the cart then runs on a fixed incline.
    thetaddot_free = thetaddot
    tilt_held = TILT_STOP.holds(state, p, thetaddot, regime)
    xddot = ca.if_else(tilt_held, rhs_x / m_x, xddot)
    thetaddot = ca.if_else(tilt_held, 0.0, thetaddot)
    cart_held = TRACK_STOP.holds(state, p, xddot, regime)
    derivative = ca.vertcat(
        ca.if_else(cart_held, 0.0, xdot),
        ca.if_else(cart_held, 0.0, xddot),
        ca.if_else(tilt_held, 0.0, thetadot),
        thetaddot,
    )
    return derivative, {**signals, "F_friction": F_friction, "xddot_free": xddot, "thetaddot_free": thetaddot_free}


def regime_at(state: ca.SX, V: ca.SX, p: dict[str, ca.SX], t: ca.SX, regime: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Event update of the Model Exchange seesaw: the plant's :func:`~pendulab.model.plant.switches_at` with the
    seesaw's mechanics, the track's stops and the tilt's. Returns the new :data:`REGIME` and the state after the
    event (changed only where the cart or the seesaw hits a stop)."""
    friction, current_mode, stops, new_state = switches_at(
        state, V, p, regime, lambda s, r: seesaw_equations(s, V, p, t, regime=r)[1], (TRACK_STOP, TILT_STOP))
    return ca.vertcat(friction, current_mode, *stops), new_state


def event_indicators(state: ca.SX, V: ca.SX, p: dict[str, ca.SX], t: ca.SX, regime: ca.SX) -> ca.SX:
    """The zero-crossing functions of :data:`EVENT_INDICATORS`."""
    signals = seesaw_equations(state, V, p, t, regime=regime)[1]
    return switch_indicators(state, p, V, regime, signals, (TRACK_STOP, TILT_STOP))


def _clamp_to_stop(position: ca.SX, speed: ca.SX, limit: ca.SX) -> tuple[ca.SX, ca.SX]:
    """A sub-step that carries a coordinate past its stop ends on the stop, with no outward speed."""
    clamped = ca.fmin(ca.fmax(position, -limit), limit)
    speed = ca.if_else(position >= limit, ca.fmin(speed, 0.0), ca.if_else(position <= -limit, ca.fmax(speed, 0.0), speed))
    return clamped, speed


@dataclass(frozen=True)
class SeesawModel:
    """Numerical CasADi functions of the seesaw, built from :func:`seesaw_equations`.

    Attributes
    ----------
    ode : casadi.Function
        ``seesaw_ode(state[4], V, p[np], t) -> derivative[4]``
    outputs : casadi.Function
        ``seesaw_outputs(state[4], V, p[np], t) -> [theta_measured, x_measured, V_applied, F_friction]``
    rk4 : casadi.Function
        ``seesaw_rk4(state[4], V, p[np], t, h) -> state after one RK4 step of length h``
    functions : tuple of casadi.Function
        Those three and Model Exchange's ``seesaw_ode_regime``, ``seesaw_indicators``, ``seesaw_event`` (the
        plant's :attr:`~pendulab.model.plant.PlantModel.functions`, for the seesaw: the FMU's generated C).
    """

    @property
    def ode(self) -> ca.Function:
        return _functions()[0]

    @property
    def outputs(self) -> ca.Function:
        return _functions()[1]

    @property
    def rk4(self) -> ca.Function:
        return _functions()[2]

    @property
    def functions(self) -> tuple[ca.Function, ...]:
        return (*_functions(), *_regime_functions())

    def simulate(
        self,
        params: SeesawParameters,
        V: Sequence[float] | np.ndarray,
        step: float = 1e-3,
        x0: Sequence[float] = (0.0, 0.0, 0.0, 0.0),
        substep: float = MAX_SUBSTEP,
    ) -> np.ndarray:
        """Reference integration: RK4 sub-steps, voltage held per step; the states at ``t = 0, step, ...``."""
        n_sub = substeps(step, substep)
        h = step / n_sub
        p = np.asarray(params.as_vector())
        out = np.empty((len(V) + 1, 4))
        out[0] = state = np.asarray(x0, dtype=float)
        for k, v in enumerate(np.asarray(V, dtype=float)):
            for i in range(n_sub):
                state = np.asarray(self.rk4(state, v, p, k * step + i * h, h)).ravel()
            out[k + 1] = state
        return out


@lru_cache(maxsize=None)
def _functions() -> tuple[ca.Function, ca.Function, ca.Function]:
    state, V, t, h = ca.SX.sym("state", 4), ca.SX.sym("V"), ca.SX.sym("t"), ca.SX.sym("h")
    pvec = ca.SX.sym("p", len(SeesawParameters.names()))
    p = {name: pvec[i] for i, name in enumerate(SeesawParameters.names())}
    names = ["state", "V", "p", "t"]
    derivative, signals = seesaw_equations(state, V, p, t)
    ode = ca.Function("seesaw_ode", [state, V, pvec, t], [derivative], names, ["derivative"])
    measured = ca.vertcat(quantize(state[2], p["q_theta"]), quantize(state[0], p["q_x"]), signals["V_applied"], signals["F_friction"])
    outputs = ca.Function("seesaw_outputs", [state, V, pvec, t], [measured], names, ["y"])
    tap = mean_poke_acceleration(_tap(p), t, h)  # the pulse's impulse exact wherever its edges fall

    def f(s: ca.SX) -> ca.SX:
        return seesaw_equations(s, V, p, t, tap=tap)[0]

    k1 = f(state)
    k2 = f(state + h / 2 * k1)
    k3 = f(state + h / 2 * k2)
    k4 = f(state + h * k3)
    stepped = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    x, xdot = _clamp_to_stop(stepped[0], stepped[1], p["track_half_length"])
    theta, thetadot = _clamp_to_stop(stepped[2], stepped[3], p["theta_stop"])
    rk4 = ca.Function("seesaw_rk4", [state, V, pvec, t, h], [ca.vertcat(x, xdot, theta, thetadot)], [*names, "h"], ["next"])
    return ode, outputs, rk4


@lru_cache(maxsize=None)
def _regime_functions() -> tuple[ca.Function, ca.Function, ca.Function]:
    state, V, t = ca.SX.sym("state", 4), ca.SX.sym("V"), ca.SX.sym("t")
    pvec, regime = ca.SX.sym("p", len(SeesawParameters.names())), ca.SX.sym("regime", len(REGIME))
    p = {name: pvec[i] for i, name in enumerate(SeesawParameters.names())}
    args, names = [state, V, pvec, t, regime], ["state", "V", "p", "t", "regime"]
    ode = ca.Function("seesaw_ode_regime", args, [seesaw_equations(state, V, p, t, regime=regime)[0]], names, ["derivative"])
    indicators = ca.Function("seesaw_indicators", args, [event_indicators(state, V, p, t, regime)], names, ["z"])
    update = ca.Function("seesaw_event", args, [*regime_at(state, V, p, t, regime)], names, ["regime_next", "state_next"])
    return ode, indicators, update


# ---------------------------------------------------------------------------------------------- linear
OUTPUT_NAMES = ("theta", "x")


@dataclass(frozen=True)
class LinearSeesaw:
    """The seesaw linearized about level with the cart centred.

    Attributes
    ----------
    ss : control.StateSpace
        States ``x, xdot, theta, thetadot``; input ``V``; outputs ``theta, x``.
    params : SeesawParameters
        The parameters it was linearized with (nonlinearities off).
    """

    ss: control.StateSpace
    params: SeesawParameters

    def tf(self, output: str = "theta") -> control.TransferFunction:
        """Minimal transfer function from ``V`` to ``output`` (``theta`` or ``x``)."""
        index = OUTPUT_NAMES.index(output)
        siso = control.ss(self.ss.A, self.ss.B, self.ss.C[index : index + 1, :], self.ss.D[index : index + 1, :])
        return control.minreal(control.tf(siso), tol=1e-6, verbose=False)

    @property
    def poles(self) -> np.ndarray:
        """Open-loop poles, sorted by real part."""
        poles = np.linalg.eigvals(self.ss.A)
        return poles[np.lexsort((poles.imag, poles.real))]


def linearize_seesaw(params: SeesawParameters | None = None) -> LinearSeesaw:
    """Linearize the CasADi seesaw about ``x = xdot = theta = thetadot = 0``, ``V = 0``.

    Examples
    --------
    >>> from pendulab.model.seesaw import linearize_seesaw
    >>> lin = linearize_seesaw()
    >>> int((lin.poles.real > 0).sum())     # the seesaw alone is unstable
    1
    """
    params = (params or SeesawParameters()).without_nonlinearities()
    state, V = ca.SX.sym("s", 4), ca.SX.sym("V")
    f = SeesawModel().ode(state, V, params.as_vector(), 0.0)
    jac = ca.Function("seesaw_linearization", [state, V], [ca.jacobian(f, state), ca.jacobian(f, V)])
    A, B = (np.array(m, dtype=float) for m in jac(np.zeros(4), 0.0))
    C = np.zeros((2, 4))
    C[0, 2] = C[1, 0] = 1.0
    ss = control.ss(A, B, C, np.zeros((2, 1)), states=list(STATES), inputs=["V"], outputs=list(OUTPUT_NAMES), name="seesaw")
    return LinearSeesaw(ss=ss, params=params)
