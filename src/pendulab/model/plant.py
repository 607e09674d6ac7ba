"""The one symbolic model of the cart-pendulum plant, in CasADi.

Everything that needs the plant's equations takes them from here: the plant FMU's C code (generated
by :meth:`PlantModel.generate_c`), the linearization (:mod:`pendulab.model.linear`), the Python
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
from pathlib import Path
from typing import Sequence

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


def plant_equations(
    state: ca.SX,
    V: ca.SX,
    p: dict[str, ca.SX],
    t: ca.SX,
    *,
    smooth_friction: bool = False,
    poke: ca.SX | None = None,
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

    Returns
    -------
    derivative : SX (4,)
    signals : dict
        ``V_applied``, ``current``, ``F_motor``, ``F_friction``.
    """
    xdot, alpha, alphadot = state[1], state[2], state[3]  # the position x enters no force

    # Amplifier: voltage saturation, then the optional current limit on (V - back-EMF)/Rm.
    V_applied = ca.fmin(ca.fmax(V, -p["V_max"]), p["V_max"])
    omega_m = p["Kg"] * xdot / p["r_mp"]
    current = (V_applied - p["Km"] * omega_m) / p["Rm"]
    current = ca.if_else(p["I_max"] > 0, ca.fmin(ca.fmax(current, -p["I_max"]), p["I_max"]), current)
    F_motor = p["force_gain"] * p["eta_g"] * p["Kg"] * p["eta_m"] * p["Kt"] * current / p["r_mp"]

    # Stick-slip friction (the lab's calibrated model).
    if smooth_friction:
        speed = ca.sqrt(xdot**2 + 1e-8)
        force = ca.sqrt(F_motor**2 + 1e-6)
        stick = _smooth_step(p["v1"] - speed, 2e-3) * _smooth_step(p["F1"] - force, 0.05)
        slip = _smooth_step(p["v2"] - speed, 5e-3) * _smooth_step(p["F2"] - force, 0.05)
        F_friction = -stick * F_motor - (1 - stick) * slip * p["B"] * xdot
    else:
        sticks = ca.logic_and(ca.fabs(xdot) < p["v1"], ca.fabs(F_motor) < p["F1"])
        slips = ca.logic_and(ca.fabs(xdot) < p["v2"], ca.fabs(F_motor) < p["F2"])
        F_friction = ca.if_else(sticks, -F_motor, ca.if_else(slips, -p["B"] * xdot, 0.0))
    F = F_motor + F_friction

    Mc = p["M_cart"] + p["eta_g"] * p["Kg"] ** 2 * p["Jm"] / p["r_mp"] ** 2
    Mp, lp, Ip = p["Mp"], p["lp"], p["Ip"]
    if poke is None:
        poke = poke_acceleration(p, t)

    cart_force = F - p["Beq"] * xdot - Mp * lp * ca.sin(alpha) * alphadot**2
    gravity_torque = Mp * p["g"] * lp * ca.sin(alpha) - p["Bp"] * alphadot
    D = (Mc + Mp) * Ip + Mc * Mp * lp**2 + Mp**2 * lp**2 * ca.sin(alpha) ** 2
    # Without a pendulum (calibration ramps) D = 0: the cart alone obeys Mc xddot = F - Beq xdot.
    has_pendulum = Ip + Mp * lp**2 > 0
    D_safe = ca.if_else(has_pendulum, D, 1.0)
    xddot = ca.if_else(
        has_pendulum,
        ((Ip + Mp * lp**2) * cart_force + Mp * lp * ca.cos(alpha) * gravity_torque) / D_safe,
        (F - p["Beq"] * xdot) / Mc,
    )
    alphaddot = ca.if_else(
        has_pendulum,
        (Mp * lp * ca.cos(alpha) * cart_force + (Mc + Mp) * gravity_torque) / D_safe + poke,
        0.0,
    )
    derivative = ca.vertcat(xdot, xddot, alphadot, alphaddot)
    signals = {"V_applied": V_applied, "current": current, "F_motor": F_motor, "F_friction": F_friction}
    return derivative, signals


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

    def generate_c(self, directory: Path, name: str = "plant_casadi") -> Path:
        """Write the C code of ``plant_ode``, ``plant_outputs`` and ``plant_rk4`` to ``directory``.

        Returns the path of the ``.c`` file; a header of the same stem is written beside it.
        """
        directory.mkdir(parents=True, exist_ok=True)
        gen = ca.CodeGenerator(f"{name}.c", {"with_header": True, "casadi_real": "double", "casadi_int": "long long int"})
        for function in (self.ode, self.outputs, self.rk4):
            gen.add(function)
        gen.generate(str(directory) + "/")
        return directory / f"{name}.c"

    def simulate(
        self,
        params: PlantParameters,
        V: Sequence[float] | np.ndarray,
        step: float = 1e-3,
        x0: Sequence[float] = (0.0, 0.0, 0.0, 0.0),
        substep: float = MAX_SUBSTEP,
    ) -> np.ndarray:
        """Reference integration: RK4 sub-steps of the CasADi right-hand side, voltage held per step.

        Parameters
        ----------
        V : array (n,)
            Voltage held during each communication step of length ``step``.

        Returns
        -------
        array (n+1, 4)
            The states at ``t = 0, step, ..., n*step``.
        """
        V = np.asarray(V, dtype=float)
        n_sub = substeps(step, substep)
        h = step / n_sub
        # The mapped function integrates one communication step per call (fast in CasADi's VM).
        one_step = _step_function(self.smooth_friction, n_sub)
        p = np.asarray(params.as_vector())
        out = np.empty((len(V) + 1, 4))
        out[0] = x0
        state = np.asarray(x0, dtype=float)
        for k, v in enumerate(V):
            state = np.asarray(one_step(state, v, p, k * step, h)).ravel()
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
    rk4 = ca.Function("plant_rk4", [state, V, pvec, t, h], [stepped], ["state", "V", "p", "t", "h"], ["next"])
    return ode, outputs, rk4


@lru_cache(maxsize=None)
def _step_function(smooth_friction: bool, n_sub: int) -> ca.Function:
    rk4 = _functions(smooth_friction)[2]
    state = ca.MX.sym("state", 4)
    V, t, h = ca.MX.sym("V"), ca.MX.sym("t"), ca.MX.sym("h")
    p = ca.MX.sym("p", len(PlantParameters.names()))
    s = state
    for i in range(n_sub):
        s = rk4(s, V, p, t + i * h, h)
    return ca.Function("plant_step", [state, V, p, t, h], [s])
