"""Worked example of a custom block: full-state-feedback (LQR) balance with cart re-centring.

The block measures what the rig measures, the cart position and the pendulum angle, and estimates
both velocities itself by a filtered difference (the derivative ``s / (tau s + 1)`` discretized
backward-Euler at the step ``h``)::

    v[k] = (tau * v[k-1] + y[k] - y[k-1]) / (tau + h)

and commands ``V = -(K_x (x - x_ref) + K_xdot xdot + K_alpha alpha + K_alphadot alphadot)``. The
position term is what brings the cart back to ``x_ref`` (the track centre) after a poke.

The gains come from :func:`design_lqr`: ``control.lqr`` (which solves the Riccati equation with
SciPy, no slycot needed) on the linearized plant of :func:`pendulab.model.linear.linearize`.
The FMU is generic: the gains are parameters; :func:`build_lqr_controller` bakes a design into
the FMU's start values.

Examples
--------
>>> from pendulab.blocks.lqr import design_lqr
>>> design = design_lqr()                        # long pendulum, default weights
>>> bool(all(design.closed_loop_poles.real < 0))
True

Build it with :func:`build_lqr_controller` and run it with :func:`pendulab.simulate` (example in
:mod:`pendulab.blocks.loop`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pendulab.blocks.base import Block, Var
from pendulab.errors import UserError

if TYPE_CHECKING:  # the block itself runs without numpy/control; only the design needs them
    import numpy as np

    from pendulab.model.parameters import PlantParameters

#: Default state weights (x, xdot, alpha, alphadot) and voltage weight of the design (Bryson's rule:
#: 1 / acceptable deviation squared, about 2 cm and 1.3 deg per volt). A brisk cart-position loop
#: keeps the cart's stiction from turning the re-centring into a slow stick-slip oscillation.
DEFAULT_Q = (2000.0, 0.0, 2000.0, 0.0)
DEFAULT_R = 1.0
#: Default time constant of the velocity estimators (s): long enough to smooth the angle encoder's
#: 1 mrad steps (a step over one 1 ms sample is 1 rad/s raw), short against the 0.2 s balance dynamics.
DEFAULT_TAU = 0.008
GAIN_NAMES = ("K_x", "K_xdot", "K_alpha", "K_alphadot")


class LQRController(Block):
    """Full-state feedback with cart re-centring, velocities from filtered differences."""

    author = "pendulab"
    inputs = {
        "alpha_measured": Var(0.0, "rad", "Measured pendulum angle from upright"),
        "x_measured": Var(0.0, "m", "Measured cart position (0 at track centre)"),
    }
    outputs = {
        "V_command": Var(0.0, "V", "Voltage command -(K_x (x - x_ref) + K_xdot xdot + K_alpha alpha + K_alphadot alphadot)"),
        "xdot_estimate": Var(0.0, "m/s", "Cart velocity estimate (filtered difference of x_measured)"),
        "alphadot_estimate": Var(0.0, "rad/s", "Pendulum angular velocity estimate (filtered difference of alpha_measured)"),
    }
    parameters = {
        "K_x": Var(0.0, "V/m", "State-feedback gain on the cart position"),
        "K_xdot": Var(0.0, "V.s/m", "State-feedback gain on the cart velocity"),
        "K_alpha": Var(0.0, "V/rad", "State-feedback gain on the pendulum angle"),
        "K_alphadot": Var(0.0, "V.s/rad", "State-feedback gain on the pendulum angular velocity"),
        "tau": Var(DEFAULT_TAU, "s", "Time constant of the velocity estimators' low-pass filter (0: plain difference)"),
        "x_ref": Var(0.0, "m", "Cart position to re-centre to", tunable=True),
        "Lp": Var(0.6413, "m", "Pendulum length of the rig (set by the system)"),
        "Lp_design": Var(0.0, "m", "Pendulum length the gains were designed for (0: not recorded)"),
    }

    def initialize(self, t: float) -> None:
        if all(getattr(self, name) == 0.0 for name in GAIN_NAMES):
            raise UserError("LQRController has no gains (all zero); build it with build_lqr_controller() or set K_x, K_xdot, K_alpha, K_alphadot")
        if self.tau < 0:
            raise UserError(f"LQRController: tau = {self.tau} s must be 0 or positive")
        if self.Lp_design > 0 and abs(self.Lp - self.Lp_design) > 1e-6 * self.Lp_design:
            self.warn(f"LQRController: gains designed for Lp = {self.Lp_design} m run on Lp = {self.Lp} m; design them for this pendulum")
        self._previous: tuple[float, float] | None = None
        self.xdot_estimate = self.alphadot_estimate = 0.0

    def step(self, t: float, h: float) -> None:
        x, alpha = self.x_measured, self.alpha_measured
        if self._previous is not None:
            x_prev, alpha_prev = self._previous
            self.xdot_estimate = (self.tau * self.xdot_estimate + x - x_prev) / (self.tau + h)
            self.alphadot_estimate = (self.tau * self.alphadot_estimate + alpha - alpha_prev) / (self.tau + h)
        self._previous = (x, alpha)
        self.V_command = -(
            self.K_x * (x - self.x_ref)
            + self.K_xdot * self.xdot_estimate
            + self.K_alpha * alpha
            + self.K_alphadot * self.alphadot_estimate
        )


@dataclass(frozen=True)
class LQRDesign:
    """An LQR design on the linearized plant (state order ``x, xdot, alpha, alphadot``).

    Attributes
    ----------
    K : ndarray, shape (4,)
        Gains of ``V = -K s``.
    closed_loop_poles : ndarray
        Eigenvalues of ``A - B K`` (continuous time, ideal state measurement).
    """

    K: np.ndarray
    Q: np.ndarray
    R: float
    closed_loop_poles: np.ndarray
    Lp: float

    def start_values(self, *, tau: float = DEFAULT_TAU) -> dict[str, float]:
        """Start values of :class:`LQRController` for this design."""
        return {**{name: float(k) for name, k in zip(GAIN_NAMES, self.K)}, "tau": float(tau), "Lp": self.Lp, "Lp_design": self.Lp}


def design_lqr(
    params: PlantParameters | None = None,
    *,
    q: tuple[float, float, float, float] = DEFAULT_Q,
    r: float = DEFAULT_R,
) -> LQRDesign:
    """LQR gains for the linearized plant: minimize the integral of ``s' diag(q) s + r V^2``.

    Examples
    --------
    >>> d = design_lqr(q=(100.0, 0.0, 100.0, 0.0), r=1.0)
    >>> round(float(d.K[0]), 6)          # sqrt(q_x / r), the textbook result for an integrator chain
    -10.0
    """
    import control
    import numpy as np

    from pendulab.model.linear import linearize
    from pendulab.model.parameters import PlantParameters

    params = params or PlantParameters.preset()
    Q = np.diag(np.asarray(q, dtype=float))
    if Q.shape != (4, 4) or np.any(np.diag(Q) < 0) or not r > 0:
        raise UserError("LQR weights: q needs 4 non-negative entries (x, xdot, alpha, alphadot) and r must be positive")
    plant = linearize(params).ss
    K, _, poles = control.lqr(plant.A, plant.B, Q, np.array([[float(r)]]))
    return LQRDesign(K=np.asarray(K, dtype=float).ravel(), Q=Q, R=float(r), closed_loop_poles=np.asarray(poles), Lp=params.Lp)


def build_lqr_controller(
    out: str | Path = ".",
    params: PlantParameters | None = None,
    *,
    q: tuple[float, float, float, float] = DEFAULT_Q,
    r: float = DEFAULT_R,
    tau: float = DEFAULT_TAU,
) -> Path:
    """Design the LQR for ``params`` and build ``LQRController.fmu`` with those gains as defaults."""
    from pendulab.blocks.build import build_block

    design = design_lqr(params, q=q, r=r)
    return build_block(LQRController, out, start_values=design.start_values(tau=tau))


def lqr_parameters(params: PlantParameters | None = None, **kwargs: Any) -> dict[str, float]:
    """Start values of a design, to set on an already built LQRController FMU."""
    tau = kwargs.pop("tau", DEFAULT_TAU)
    return design_lqr(params, **kwargs).start_values(tau=tau)
