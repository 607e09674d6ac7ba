"""Linearization of the CasADi plant about the upright equilibrium, as python-control systems.

Examples
--------
>>> from pendulab.model.linear import linearize
>>> lin = linearize()                      # long pendulum, IP02 no-load cart
>>> z, p, k = lin.zpk("alpha")
>>> round(k, 2)
5.25
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import control
import numpy as np

from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import STATES, PlantModel

OUTPUT_NAMES = ("alpha", "x", "tip")


@dataclass(frozen=True)
class LinearPlant:
    """The linearized plant: state-space with named signals, and its transfer functions.

    Attributes
    ----------
    ss : control.StateSpace
        States ``x, xdot, alpha, alphadot``; input ``V``; outputs ``alpha, x, tip``.
    params : PlantParameters
        The parameters it was linearized with.
    """

    ss: control.StateSpace
    params: PlantParameters

    def tf(self, output: str = "alpha") -> control.TransferFunction:
        """Minimal transfer function from ``V`` to ``output`` (``alpha``, ``x`` or ``tip``)."""
        index = OUTPUT_NAMES.index(output)
        siso = control.ss(self.ss.A, self.ss.B, self.ss.C[index : index + 1, :], self.ss.D[index : index + 1, :])
        # Cancel the pole-zero pairs at s = 0 that the cart position leaves in alpha/V, and drop the
        # round-off left in the leading coefficients (it would show as a zero near infinity).
        g = control.minreal(control.tf(siso), tol=1e-6, verbose=False)
        return control.tf(_trim(g.num[0][0]), _trim(g.den[0][0]))

    def zpk(self, output: str = "alpha") -> tuple[np.ndarray, np.ndarray, float]:
        """Zeros, poles and gain of the minimal transfer function.

        The gain is the leading coefficient ratio: ``G(s) = k * prod(s - z) / prod(s - p)``.
        """
        g = self.tf(output)
        num, den = np.atleast_1d(g.num[0][0]), np.atleast_1d(g.den[0][0])
        zeros = _clean(np.roots(num))
        poles = _clean(np.roots(den))
        return zeros, poles, float(num[0] / den[0])


def linearize(params: PlantParameters | None = None) -> LinearPlant:
    """Linearize about ``x = xdot = alpha = alphadot = 0``, ``V = 0``.

    Friction, quantization, the current limit and the poke are switched off first (they are not
    differentiable at the equilibrium, or are not part of the plant's small-signal behaviour).

    Parameters
    ----------
    params : PlantParameters, optional
        The plant (default: long pendulum, IP02 cart without load).

    Returns
    -------
    LinearPlant
        ``.ss`` (python-control state space), ``.tf(output)``, ``.zpk(output)``.

    Examples
    --------
    >>> lin = linearize(PlantParameters.preset("short"))
    >>> lin.ss.nstates, lin.ss.ninputs, lin.ss.noutputs
    (4, 1, 3)
    """
    params = (params or PlantParameters.preset()).without_nonlinearities()
    ode = PlantModel().ode
    state, V = ca.SX.sym("s", 4), ca.SX.sym("V")
    p = params.as_vector()
    f = ode(state, V, p, 0.0)
    jac = ca.Function("plant_linearization", [state, V], [ca.jacobian(f, state), ca.jacobian(f, V)])
    A, B = (np.array(m, dtype=float) for m in jac(np.zeros(4), 0.0))
    C = np.zeros((3, 4))
    C[0, 2] = 1.0  # alpha
    C[1, 0] = 1.0  # x
    C[2, 2] = params.Lp  # tip = Lp * alpha (arc length at the tip)
    ss = control.ss(A, B, C, np.zeros((3, 1)), states=list(STATES), inputs=["V"], outputs=list(OUTPUT_NAMES), name="plant")
    return LinearPlant(ss=ss, params=params)


def tf(params: PlantParameters | None = None, output: str = "alpha") -> control.TransferFunction:
    """The plant's minimal transfer function from the voltage ``V`` to ``output``, linearized upright.

    Parameters
    ----------
    params : PlantParameters, optional
        The plant (default: long pendulum, IP02 cart without load); a calibrated plant gives the
        calibrated transfer function.
    output : {"alpha", "x", "tip"}
        Pendulum angle (rad), cart position (m) or tip position ``Lp*alpha`` (m).

    Returns
    -------
    control.TransferFunction

    Examples
    --------
    >>> g = tf()                                      # alpha/V, the lab's 5.247 s / ((s+16.26)(s+4.561)(s-4.843))
    >>> [round(float(c), 3) for c in g.num[0][0]]
    [5.247, 0.0]
    """
    return linearize(params).tf(output)


def _trim(coefficients: np.ndarray) -> np.ndarray:
    """Polynomial coefficients without the round-off residue left in leading positions."""
    c = np.atleast_1d(np.asarray(coefficients, dtype=float))
    keep = np.abs(c) > 1e-10 * np.max(np.abs(c))
    return c[np.argmax(keep):] if keep.any() else c[-1:]


def _clean(values: np.ndarray) -> np.ndarray:
    """Roots sorted by real part, with numerically-zero imaginary parts dropped."""
    values = np.asarray(values, dtype=complex)
    values = np.where(np.abs(values.imag) < 1e-9 * np.maximum(1, np.abs(values)), values.real, values)
    order = np.lexsort((values.imag, values.real))
    values = values[order]
    return values.real if np.all(values.imag == 0) else values
