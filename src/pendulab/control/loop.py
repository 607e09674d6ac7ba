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
