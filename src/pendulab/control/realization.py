"""A numerically sound discrete state-space realization of the controller (SPEC §4, *Realization*).

The controller FMU is a generic discrete LTI block ``x[k+1] = A x[k] + B e[k]``,
``V[k] = C x[k] + D e[k]`` whose matrices are FMU parameters. They are built here:

1. The zeros and poles of all factors are grouped into first- and second-order sections (each complex
   pole pair is one section; each zero goes with the nearest pole, complex zero pairs with a pole pair
   or with two real poles), so no polynomial of degree above 2 is ever formed; the sections keep the
   order of the factors' poles.
2. Each section is a small, well-scaled state space (second-order ones in a companion form scaled by
   the natural frequency) with about unit gain, the overall gain spread evenly over the sections,
   and the sections are connected in series: a block lower-triangular ``A``.
3. Tustin (bilinear) maps a product to the product of the maps, so each section is discretized on
   its own and the discrete sections are connected in series. Zero-order hold does not factor: the
   whole block-triangular realization is discretized at once (matrix exponential). Both are the
   exact formulas of :func:`scipy.signal.cont2discrete` and keep the block structure.

A single high-order companion form of ``num(s)/den(s)`` is never built: its coefficients lose the
roots of a high-order controller to round-off.

Examples
--------
>>> import numpy as np
>>> from pendulab.control.controller import demo_controller
>>> from pendulab.control.realization import discretize
>>> lti = discretize(demo_controller(), h=1e-3, method="tustin")
>>> lti.order, lti.A.shape
(3, (3, 3))
>>> p = lti.to_parameters()
>>> p["n"], sorted(p)[:3]
(3, ['A[1,1]', 'A[1,2]', 'A[1,3]'])
>>> y = lti.step_response(np.ones(5))          # response to a unit step of the tip error
>>> bool(np.isclose(y[0], lti.D[0, 0]))
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from pendulab import exact
from pendulab.control.controller import Controller, Number
from pendulab.errors import ControllerError

#: Largest controller order the controller FMU holds.
MAX_ORDER = 16
METHODS = ("tustin", "zoh")


@dataclass(frozen=True)
class DiscreteLTI:
    """``x[k+1] = A x[k] + B u[k]``, ``y[k] = C x[k] + D u[k]`` at sample period ``h``.

    Attributes
    ----------
    A : ndarray (n, n)
    B : ndarray (n, 1)
    C : ndarray (1, n)
    D : ndarray (1, 1)
    h : float
        Sample period in seconds.
    method : str
        ``"tustin"`` or ``"zoh"``.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    h: float
    method: str

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    def poles(self) -> np.ndarray:
        """Eigenvalues of ``A`` (the discrete poles)."""
        return np.linalg.eigvals(self.A) if self.order else np.zeros(0, dtype=complex)

    def step_response(self, u: Any, x0: Any = None) -> np.ndarray:
        """Output sequence ``y[0..N-1]`` for the input sequence ``u[0..N-1]`` from state ``x0`` (default 0).

        ``y[k]`` uses ``u[k]`` (direct feedthrough ``D``), as the FMU does within one step.
        """
        u = np.asarray(u, dtype=float).ravel()
        x = np.zeros(self.order) if x0 is None else np.asarray(x0, dtype=float).ravel().copy()
        A, B, C, D = self.A, self.B[:, 0], self.C[0, :], float(self.D[0, 0])
        y = np.empty_like(u)
        for k, uk in enumerate(u):
            y[k] = C @ x + D * uk
            x = A @ x + B * uk
        return y

    def transfer_function(self) -> "control.TransferFunction":  # noqa: F821
        """The discrete transfer function (for comparisons; the realization itself is what the FMU runs)."""
        if self.order == 0:
            import control

            return control.tf([float(self.D[0, 0])], [1.0], self.h)
        return control.tf(control.ss(self.A, self.B, self.C, self.D, self.h))

    def to_parameters(self) -> dict[str, float | int]:
        """Start values of the controller FMU: ``n``, ``A[i,j]``, ``B[i]``, ``C[i]``, ``D`` (1-based).

        Only entries with ``i, j <= n`` are given; the FMU's other entries stay 0.
        """
        n = self.order
        out: dict[str, float | int] = {"n": n}
        for i in range(n):
            for j in range(n):
                out[f"A[{i + 1},{j + 1}]"] = float(self.A[i, j])
        for i in range(n):
            out[f"B[{i + 1}]"] = float(self.B[i, 0])
        for i in range(n):
            out[f"C[{i + 1}]"] = float(self.C[0, i])
        out["D"] = float(self.D[0, 0])
        return out


# ---------------------------------------------------------------------------------------------- sections
@dataclass
class _Section:
    poles: list[complex]
    zeros: list[complex]

    @property
    def capacity(self) -> int:
        return len(self.poles) - len(self.zeros)

    def distance(self, z: complex) -> float:
        return min(abs(z - p) for p in self.poles)


def sections(zeros: list[Number], poles: list[Number]) -> list[tuple[list[complex], list[complex]]]:
    """Group roots into sections of 1 or 2 poles, each with no more zeros than poles.

    Conjugate pairs stay together. Returns ``[(zeros, poles), ...]`` in the order of the poles.
    """
    zeros_c = [complex(z) for z in zeros]
    poles_c = [complex(p) for p in poles]
    if len(zeros_c) > len(poles_c):
        raise ControllerError(f"G(s) is improper: {len(zeros_c)} zeros but {len(poles_c)} poles; add poles")
    secs: list[_Section] = []
    real_poles: list[_Section] = []
    for p in poles_c:
        if p.imag > 0:
            secs.append(_Section([p, p.conjugate()], []))
        elif p.imag == 0:
            s = _Section([p], [])
            secs.append(s)
            real_poles.append(s)
    # Complex zero pairs need two poles: a complex-pole section, else two real poles merged.
    for z in sorted((z for z in zeros_c if z.imag > 0), key=lambda z: -abs(z.imag)):
        pair = [z, z.conjugate()]
        free = [s for s in secs if len(s.poles) == 2 and not s.zeros]
        if free:
            best = min(free, key=lambda s: s.distance(z))
            best.zeros.extend(pair)
            continue
        empty = sorted((s for s in real_poles if not s.zeros and s in secs), key=lambda s: s.distance(z))
        if len(empty) < 2:
            raise ControllerError("cannot group the zeros into proper sections; add poles")  # unreachable when proper
        first, second = empty[0], empty[1]
        first.poles.extend(second.poles)
        first.zeros.extend(pair)
        secs.remove(second)
        real_poles.remove(second)
    # Real zeros: the nearest pole section with room left.
    for z in sorted((z for z in zeros_c if z.imag == 0), key=lambda z: abs(z)):
        room = [s for s in secs if s.capacity > 0]
        best = min(room, key=lambda s: s.distance(z))
        best.zeros.append(z)
    return [(s.zeros, s.poles) for s in secs]


def _section_ss(zeros: list[complex], poles: list[complex]) -> tuple[np.ndarray, ...]:
    """A small, well-scaled state space of ``prod(s - z) / prod(s - p)`` (1 or 2 poles)."""
    num = np.real(np.poly(zeros)) if zeros else np.array([1.0])
    den = np.real(np.poly(poles))
    num = np.concatenate([np.zeros(len(den) - len(num)), num])
    d = num[0]  # den is monic
    rest = num - d * den  # strictly proper part, rest[0] == 0
    if len(den) == 2:
        a0 = den[1]
        c0 = rest[1]
        # Balance input and output weights: B = C = sqrt(|c0|) (sign on C).
        b = np.sqrt(abs(c0)) if c0 != 0 else 1.0
        return np.array([[-a0]]), np.array([[b]]), np.array([[c0 / b]]), np.array([[d]])
    a1, a0 = den[1], den[2]
    # Companion form scaled by w = sqrt(|a0|): states w·z and z' keep entries of size w.
    w = np.sqrt(abs(a0))
    A = np.array([[0.0, w], [-a0 / w, -a1]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[rest[2] / w, rest[1]]])
    return A, B, C, np.array([[d]])


def _section_blocks(controller: Controller) -> list[tuple[np.ndarray, ...]]:
    """The sections' state spaces, each scaled to about unit gain, the overall gain spread evenly.

    Each section is normalized to gain 1 at its natural frequency (the geometric mean of its poles'
    magnitudes) and then multiplied by the same share of what is left of the overall gain, so the
    signal passed from one section to the next keeps a moderate size whatever the roots and gains.
    """
    zeros, poles, gain = controller.zpk()
    secs = sections(list(zeros), list(poles))
    if not secs:
        return []
    # Logs and exps through the C library (pendulab.exact): numpy's take other code on an AVX-512 CPU, and the sections' gains,
    # hence the controller's coefficients and a closed loop's run from its first disturbance on, differed in their last bits.
    log_norms = []
    for sz, sp in secs:
        # Gain at the natural frequency w as if the roots lay at -|r|: never 0 or infinite, even for
        # roots on the imaginary axis, and close to the true gain for ordinary sections.
        log_w = float(np.mean([exact.log(abs(p)) for p in sp]))
        size = sum(_log_hypot(log_w, exact.log(abs(z))) for z in sz) - sum(_log_hypot(log_w, exact.log(abs(p))) for p in sp)
        log_norms.append(size)
    share = (exact.log(abs(gain)) - sum(log_norms)) / len(secs)
    blocks = []
    for i, ((sz, sp), log_norm) in enumerate(zip(secs, log_norms)):
        A, B, C, D = _section_ss(sz, sp)
        f = exact.exp(share + log_norm)  # this section's factor: its own normalization times the shared gain
        f = f if i or gain > 0 else -f  # the sign of the gain goes to the first section
        root = np.sqrt(abs(f))
        blocks.append((A, B * root, C * (f / root), D * f))
    return blocks


def _log_hypot(log_a: float, log_b: float) -> float:
    """``log(sqrt(a² + b²))`` from ``log a`` and ``log b`` without overflow."""
    return float(np.logaddexp(2 * log_a, 2 * log_b) / 2)


def _series(blocks: list[tuple[np.ndarray, ...]], D0: float = 1.0) -> tuple[np.ndarray, ...]:
    """Connect ``u -> block 1 -> block 2 -> ... -> y``: a block lower-triangular state matrix."""
    A = np.zeros((0, 0))
    B = np.zeros((0, 1))
    C = np.zeros((1, 0))
    D = np.array([[D0]])
    for As, Bs, Cs, Ds in blocks:
        n, m = A.shape[0], As.shape[0]
        A_new = np.zeros((n + m, n + m))
        A_new[:n, :n] = A
        A_new[n:, :n] = Bs @ C
        A_new[n:, n:] = As
        B = np.vstack([B, Bs @ D])
        C = np.hstack([Ds @ C, Cs])
        D = Ds @ D
        A = A_new
    return A, B, C, D


def continuous_realization(controller: Controller) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(A, B, C, D)`` of ``G(s)``: first/second-order sections in series (block lower-triangular ``A``)."""
    blocks = _section_blocks(controller)
    return _series(blocks, 1.0 if blocks else controller.zpk()[2])


def discretize(controller: Any, h: float = 1e-3, method: str = "tustin") -> DiscreteLTI:
    """The controller as a discrete LTI block at sample period ``h``.

    Parameters
    ----------
    controller : Controller, control.TransferFunction or control.StateSpace
        A transfer function is checked by the same entry rules (via
        :meth:`Controller.from_transfer_function`).
    h : float
        Sample period in seconds (the control period, default 1 ms).
    method : {"tustin", "zoh"}
        Bilinear transform (default) or zero-order hold.

    Raises
    ------
    ControllerError
        Order above 16, a bad ``h`` or ``method``, or a pole Tustin cannot map (at ``s = 2/h``).
    """
    if not isinstance(controller, Controller):
        import control  # only for a python-control object (importing it costs a second)

        if isinstance(controller, (control.TransferFunction, control.StateSpace)):
            controller = Controller.from_transfer_function(controller)
        else:
            raise ControllerError(f"cannot discretize a {type(controller).__name__}; give a Controller or a control.TransferFunction")
    method = str(method).lower()
    if method == "bilinear":
        method = "tustin"
    if method not in METHODS:
        raise ControllerError(f"unknown discretization method {method!r}; choose tustin or zoh")
    try:
        h = float(h)
    except (TypeError, ValueError):
        raise ControllerError(f"sample period h={h!r} is not a number; give a period in seconds, e.g. 0.001") from None
    if not (np.isfinite(h) and h > 0):
        raise ControllerError(f"sample period h={h} must be a positive number of seconds, e.g. 0.001")
    if controller.order > MAX_ORDER:
        raise ControllerError(
            f"the controller has order {controller.order} (number of poles); the controller FMU holds at most {MAX_ORDER}: remove poles"
        )
    blocks = _section_blocks(controller)
    if not blocks:
        D = np.array([[controller.zpk()[2]]])
        return DiscreteLTI(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), D, h, method)
    if method == "tustin":
        # I - A h/2 is block-triangular: it is singular exactly when a pole sits at s = 2/h.
        for p in controller.zpk()[1]:
            if abs(1 - complex(p) * h / 2) <= 1e-9 * max(1.0, abs(complex(p) * h / 2)):
                raise ControllerError(
                    f"the pole {complex(p).real:g} sits at s = 2/h = {2 / h:g} rad/s, which Tustin cannot map at h={h}; use zoh or move the pole"
                )
        # The bilinear map of a product is the product of the maps: discretize section by section
        # (1x1 and 2x2 solves only) and connect the discrete sections in series.
        Ad, Bd, Cd, Dd = _series([_bilinear(*block, h) for block in blocks])
    else:
        # A held input does not factor through the sections: the exponential of the whole
        # block-triangular realization (scipy: expm of [[A, B], [0, 0]] h).
        Ad, Bd, Cd, Dd = _zero_order_hold(*_series(blocks), h)
    arrays = [np.asarray(m, dtype=float) for m in (Ad, Bd, Cd, Dd)]
    if not all(np.all(np.isfinite(m)) for m in arrays):
        raise ControllerError(f"the discretized controller has non-finite entries (poles too fast for h={h}); move fast poles or use a smaller h")
    return DiscreteLTI(*arrays, h=h, method=method)



# The formulas of scipy.signal.cont2discrete, here so that the command line need not import
# scipy.signal (most of a second) for two small matrix operations.
def _bilinear(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, h: float) -> tuple[np.ndarray, ...]:
    """Tustin (bilinear) discretization of a state-space block."""
    eye = np.eye(A.shape[0])
    ima = eye - 0.5 * h * A
    Ad = np.linalg.solve(ima, eye + 0.5 * h * A)
    Bd = np.linalg.solve(ima, h * B)
    Cd = np.linalg.solve(ima.T, C.T).T
    Dd = D + 0.5 * (C @ Bd)
    return Ad, Bd, Cd, Dd


def _zero_order_hold(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, h: float) -> tuple[np.ndarray, ...]:
    """Zero-order-hold discretization: the exponential of ``[[A, B], [0, 0]] h``."""
    n, m = A.shape[0], B.shape[1]
    block = np.zeros((n + m, n + m))
    block[:n, :n] = A
    block[:n, n:] = B
    exp = scipy.linalg.expm(block * h)
    return exp[:n, :n], exp[:n, n:], C, D
