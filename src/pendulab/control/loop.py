"""The lab's loop in linear, sampled form: a quick check of a controller before a simulation.

The loop of SPEC §4: the controller sees the tip-position error ``e = r - Lp·alpha_measured``
(``r = 0``) and outputs the voltage command. Here the plant is the linearized model
(:func:`pendulab.model.linear.linearize`) sampled with a zero-order hold at the control period ``h``,
the controller is its discrete realization (:func:`pendulab.control.realization.discretize`), and the
voltage computed from the sample at ``t_k`` is applied from ``t_{k+delay}`` on (default one sample of
computation delay). Friction, saturation and quantization are not in this model.

The cart position ``x`` enters no equation of the linearized plant, so it is left out of the loop's
state: it would only add a pole at ``z = 1`` that the controller cannot see through ``alpha`` (the
cart's slow drift).

Examples
--------
>>> import numpy as np
>>> from pendulab.control.controller import demo_controller
>>> from pendulab.control.loop import closed_loop_poles
>>> from pendulab.model.parameters import PlantParameters
>>> poles = closed_loop_poles(demo_controller(), PlantParameters.preset("short"))
>>> bool(np.max(np.abs(poles)) < 1)
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.signal

from pendulab.control.realization import DiscreteLTI, discretize
from pendulab.errors import ControllerError
from pendulab.model.linear import linearize
from pendulab.model.parameters import PlantParameters

#: Index of the states in the linearized plant.
_X, _XDOT, _ALPHA, _ALPHADOT = range(4)


def sampled_plant(params: PlantParameters | None = None, h: float = 1e-3, *, with_cart_position: bool = False) -> tuple[np.ndarray, ...]:
    """ZOH-sampled linear plant ``(A, B, C, Bw)``: input ``V``, output ``tip = Lp·alpha``.

    ``Bw`` is the input matrix of the poke (an angular acceleration, rad/s²). Without
    ``with_cart_position`` the states are ``[xdot, alpha, alphadot]``.
    """
    params = params or PlantParameters.preset()
    ss = linearize(params).ss
    A, B = np.asarray(ss.A, dtype=float), np.asarray(ss.B, dtype=float)
    Bw = np.zeros((4, 1))
    Bw[_ALPHADOT, 0] = 1.0
    C = np.zeros((1, 4))
    C[0, _ALPHA] = params.Lp
    keep = list(range(4))
    if not with_cart_position:
        if np.any(A[:, _X] != 0):  # the position would matter after all: keep it
            raise RuntimeError("the linearized plant depends on the cart position; cannot drop it")
        keep = [_XDOT, _ALPHA, _ALPHADOT]
    A, B, Bw, C = A[np.ix_(keep, keep)], B[keep], Bw[keep], C[:, keep]
    Ad, Bd, _, _, _ = scipy.signal.cont2discrete((A, np.hstack([B, Bw]), C, np.zeros((1, 2))), h, method="zoh")
    return Ad, Bd[:, :1], C, Bd[:, 1:]


def _loop_matrix(ctl: DiscreteLTI, Ap: np.ndarray, Bp: np.ndarray, Cp: np.ndarray, delay: int) -> np.ndarray:
    """State matrix of plant + delay line + controller, with ``e = -Cp xp``."""
    n_p, n_c = Ap.shape[0], ctl.order
    Ac, Bc, Cc, Dc = ctl.A, ctl.B, ctl.C, ctl.D
    if delay == 0:
        # V[k] = Cc xc - Dc Cp xp acts during the same sample.
        top = np.hstack([Ap - Bp @ Dc @ Cp, Bp @ Cc])
        bottom = np.hstack([-Bc @ Cp, Ac])
        return np.vstack([top, bottom])
    n = n_p + delay + n_c
    M = np.zeros((n, n))
    M[:n_p, :n_p] = Ap
    M[:n_p, n_p : n_p + 1] = Bp  # the oldest command in the delay line is applied
    for i in range(delay - 1):  # shift the delay line
        M[n_p + i, n_p + i + 1] = 1.0
    last = n_p + delay - 1
    M[last, :n_p] = -(Dc @ Cp)[0]
    M[last, n_p + delay :] = Cc[0]
    M[n_p + delay :, :n_p] = -Bc @ Cp
    M[n_p + delay :, n_p + delay :] = Ac
    return M


def closed_loop_poles(
    controller: Any,
    params: PlantParameters | None = None,
    *,
    h: float = 1e-3,
    method: str = "tustin",
    delay: int = 1,
) -> np.ndarray:
    """Discrete closed-loop poles (``z``-plane) of the sampled linear loop.

    The loop is stable when all have ``|z| < 1``; ``np.log(z) / h`` gives the equivalent
    continuous poles.
    """
    if delay not in range(0, 100):
        raise ControllerError(f"delay={delay!r} samples must be an integer from 0 to 99")
    ctl = controller if isinstance(controller, DiscreteLTI) else discretize(controller, h=h, method=method)
    Ap, Bp, Cp, _ = sampled_plant(params, ctl.h)
    return np.linalg.eigvals(_loop_matrix(ctl, Ap, Bp, Cp, delay))


def poke_response(
    controller: Any,
    params: PlantParameters | None = None,
    *,
    h: float = 1e-3,
    method: str = "tustin",
    delay: int = 1,
    stop_time: float = 4.0,
) -> dict[str, np.ndarray]:
    """Response of the sampled linear loop to the poke in ``params`` (magnitude, duration, start).

    Returns arrays ``t``, ``x``, ``alpha`` (rad) and ``V`` (the applied voltage, no saturation).
    """
    params = params or PlantParameters.preset()
    ctl = controller if isinstance(controller, DiscreteLTI) else discretize(controller, h=h, method=method)
    Ap, Bp, Cp, Bw = sampled_plant(params, ctl.h, with_cart_position=True)
    n = int(round(stop_time / ctl.h))
    t = np.arange(n) * ctl.h
    # The poke as a per-sample average so that a start or duration off the grid still gives its impulse.
    w = np.clip(np.minimum(t + ctl.h, params.poke_start + params.poke_duration) - np.maximum(t, params.poke_start), 0, None)
    w *= params.poke_magnitude / ctl.h
    xp, xc = np.zeros(Ap.shape[0]), np.zeros(ctl.order)
    queue = [0.0] * delay
    out = {"t": t, "x": np.empty(n), "alpha": np.empty(n), "V": np.empty(n)}
    Ac, Bc, Cc, Dc = ctl.A, ctl.B[:, 0], ctl.C[0], float(ctl.D[0, 0])
    for k in range(n):
        e = -float(Cp[0] @ xp)
        command = float(Cc @ xc) + Dc * e
        xc = Ac @ xc + Bc * e
        queue.append(command)
        V = queue.pop(0)
        out["x"][k], out["alpha"][k], out["V"][k] = xp[_X], xp[_ALPHA], V
        xp = Ap @ xp + Bp[:, 0] * V + Bw[:, 0] * w[k]
    return out


# ------------------------------------------------------------------------------ the linear prediction
#: Gain multiples tried by :func:`linear_prediction` before it says that no gain of this shape balances.
GAIN_SCAN = np.logspace(-2.0, 2.0, 41)


@dataclass(frozen=True)
class LinearPrediction:
    """What the sampled linear loop predicts, before any simulation.

    Attributes
    ----------
    poles_z : ndarray
        Closed-loop poles of the sampled loop (``z``-plane), largest |z| first.
    h : float
        Control period (s): ``log(z)/h`` are the equivalent continuous poles.
    stable : bool
        All ``|z| < 1``.
    never : str or None
        Why no gain can balance the pendulum with this controller (None: some can).
    """

    poles_z: np.ndarray
    h: float
    stable: bool
    never: str | None = None

    @property
    def max_abs_z(self) -> float:
        return float(np.max(np.abs(self.poles_z))) if self.poles_z.size else 0.0

    @property
    def poles_s(self) -> np.ndarray:
        """Equivalent continuous poles ``log(z)/h`` (1/s), in the order of ``poles_z``."""
        with np.errstate(divide="ignore"):
            return np.log(self.poles_z.astype(complex)) / self.h

    def describe(self, count: int = 3) -> str:
        """``linear model: stable, dominant closed-loop poles s = -2.39, -2.97±4.88j (1 ms sampled loop)``."""
        shown: list[str] = []
        for s in self.poles_s:
            if len(shown) >= count:
                break
            if s.imag < -1e-9:
                continue
            text = f"{s.real:.3g}" + (f"±{abs(s.imag):.3g}j" if abs(s.imag) > 1e-9 else "")
            shown.append(text)
        word = "stable" if self.stable else "UNSTABLE"
        return f"linear model: {word}, dominant closed-loop poles s = {', '.join(shown)} (max |z| = {self.max_abs_z:.5f})"

    def agrees_with(self, outcome: str) -> bool:
        """Whether the linear loop's stability matches a simulated outcome (``balanced`` is stable)."""
        return self.stable == (outcome == "balanced")


def never_balances(controller: Any, params: PlantParameters | None = None) -> str | None:
    """Why this controller's shape can never balance the pendulum (the sign rule), or None.

    ``alpha/V`` has a zero at ``s = 0``, so the closed loop's characteristic polynomial at ``s = 0``
    is ``den_G(0)·den_C(0)`` whatever the gain, and its leading coefficient is 1. ``den_G(0) < 0``
    (one plant pole in the right half plane), so a stable loop needs ``den_C(0) < 0``: an odd number
    of controller poles on the positive real axis. A PID (poles at ``-1/Ti`` and ``-wf``) has none.

    Examples
    --------
    >>> from pendulab.control.controller import Controller, demo_controller
    >>> never_balances(demo_controller()) is None
    True
    >>> never_balances(Controller.pid(40, 5, 4)).split(":")[0]
    'no gain can balance the pendulum with this controller'
    """
    params = params or PlantParameters.preset()
    zeros, poles, _ = linearize(params).zpk("alpha")
    if not np.any(np.abs(zeros) < 1e-9):
        return None
    den_g0 = float(np.real(np.prod(-np.asarray(poles, dtype=complex))))
    _, c_poles, _ = controller.zpk() if hasattr(controller, "zpk") else (None, np.asarray(controller.poles(), dtype=complex), None)
    c_poles = np.asarray(c_poles, dtype=complex)
    den_c0 = float(np.real(np.prod(-c_poles))) if c_poles.size else 1.0
    if den_g0 * den_c0 > 0:
        return None
    unstable_plant = ", ".join(f"{p.real:+.3g}" for p in np.asarray(poles, dtype=complex) if p.real > 0)
    rhp = int(np.sum((np.abs(c_poles.imag) < 1e-12) & (c_poles.real > 0)))
    return (
        "no gain can balance the pendulum with this controller: alpha/V has a zero at s = 0, so the closed loop's "
        f"characteristic polynomial at s = 0 is den_G(0)·den_C(0), and den_G(0) < 0 (the plant's pole at {unstable_plant}); "
        f"the controller has {rhp} pole(s) on the positive real axis, so den_C(0) > 0 and a closed-loop pole stays in the right "
        "half plane. Give it an odd number of unstable poles, as the demo's kernel (s + 5)/(s - 7) does: e.g. a PID "
        "in series with 1/(s - 4), --pid 300,100,100 --compensator \"none;4\", balances both pendulums"
    )


def linear_prediction(
    controller: Any,
    params: PlantParameters | None = None,
    *,
    h: float = 1e-3,
    method: str = "tustin",
    delay: int = 0,
) -> LinearPrediction:
    """Closed-loop poles of the sampled linear loop as simulated, and whether any gain could balance.

    ``delay`` is the transport delay of ``pendulab simulate --delay`` (control periods); the loop adds
    the one sample of computation, as :func:`closed_loop_poles` documents.

    Examples
    --------
    >>> from pendulab.control.controller import demo_controller
    >>> p = linear_prediction(demo_controller())
    >>> p.stable, p.never
    (True, None)
    """
    ctl = controller if isinstance(controller, DiscreteLTI) else discretize(controller, h=h, method=method)
    z = closed_loop_poles(ctl, params, delay=1 + max(int(delay), 0))
    z = z[np.argsort(-np.abs(z))]
    stable = bool(np.max(np.abs(z)) < 1) if z.size else True
    never = None if isinstance(controller, DiscreteLTI) else never_balances(controller, params)
    if never is None and not stable:
        Ap, Bp, Cp, _ = sampled_plant(params, ctl.h)
        works = [k for k in (*GAIN_SCAN, *(-GAIN_SCAN))
                 if np.max(np.abs(np.linalg.eigvals(_loop_matrix(_scaled(ctl, k), Ap, Bp, Cp, 1 + max(int(delay), 0))))) < 1]
        if not works:
            never = (f"no gain balances this controller's shape: the sampled linear loop is unstable for every gain from "
                     f"{GAIN_SCAN[0]:g}x to {GAIN_SCAN[-1]:g}x the given one, of either sign; move its zeros and poles")
        elif all(k < 0 for k in works):
            never = "the gain has the wrong sign for this controller's shape: only a gain of the opposite sign balances in the linear loop"
    return LinearPrediction(z, ctl.h, stable, never)


def _scaled(ctl: DiscreteLTI, k: float) -> DiscreteLTI:
    """The same realization with its output (the voltage) scaled by ``k``."""
    return DiscreteLTI(ctl.A, ctl.B, k * ctl.C, k * ctl.D, ctl.h, ctl.method)
