"""State feedback (LQR) for either plant: the pendulum on its cart, or the seesaw.

The feedback vector is ordered positions first, then velocities, then the optional integral of the angle,
as Quanser's courseware orders it: ``[x, angle, xdot, angledot(, integral of angle)]``, where the angle is
``alpha`` (pendulum) or ``theta`` (seesaw). The control law is ``V = -K state``.

Quanser's seesaw lab (``setup_ip02_ssw.m``) uses Q = diag(1000, 5000, 0, 0, 2000) and R = 0.5 with the
integral, and estimates the velocities with second-order derivative filters (10 Hz, damping 0.9); its
integral is limited to +/-10 degrees. Those are the seesaw's defaults here.

Examples
--------
>>> from pendulab.control.state_feedback import design_state_feedback
>>> design = design_state_feedback("seesaw")
>>> [round(float(k), 1) for k in design.K]          # the SEESAW Laboratory Guide prints 180.797 -224.3485 ...
[180.8, -224.3, 16.7, -67.0, -63.2]
>>> bool(all(design.closed_loop_poles.real < 0))
True
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from pendulab.errors import UserError

PLANTS = ("pendulum", "seesaw")
#: Default weights per plant: (Q diagonal, R, integral).
DEFAULTS = {
    "seesaw": ((1000.0, 5000.0, 0.0, 0.0, 2000.0), 0.5, True),
    # Bryson's rule as in the LQR block example (pendulab.blocks.lqr): about 2 cm and 1.3 deg per volt.
    "pendulum": ((2000.0, 2000.0, 0.0, 0.0), 1.0, False),
}
#: Quanser's velocity estimate: a second-order derivative filter, 10 Hz, damping 0.9 (setup_ip02_ssw.m).
FILTER_HZ, FILTER_ZETA = 10.0, 0.9
#: Quanser's limit on the tilt's integral (MAX_I_WINDUP = 10 deg, setup_ip02_ssw.m).
INTEGRAL_LIMIT = math.radians(10.0)


def state_names(plant: str, integral: bool) -> tuple[str, ...]:
    """The feedback vector's order for ``plant``."""
    angle = "alpha" if plant == "pendulum" else "theta"
    names = ("x", angle, "xdot", f"{angle}dot")
    return (*names, f"{angle}_integral") if integral else names


@dataclass(frozen=True)
class StateFeedbackDesign:
    """An LQR design: the gain, the closed loop's poles and everything that made them.

    Attributes
    ----------
    plant : {"pendulum", "seesaw"}
    states : tuple of str
        The feedback vector's order (:func:`state_names`).
    K : tuple of float
        Gains, ``V = -K state``.
    closed_loop_poles : numpy.ndarray
        Eigenvalues of ``A - B K`` of the continuous linear model.
    q, r : weights of the design.
    """

    plant: str
    states: tuple[str, ...]
    K: tuple[float, ...]
    closed_loop_poles: np.ndarray = field(compare=False)
    q: tuple[float, ...] = ()
    r: float = math.nan
    filter_hz: float = FILTER_HZ
    filter_zeta: float = FILTER_ZETA
    integral_limit: float = INTEGRAL_LIMIT

    @property
    def integral(self) -> bool:
        return len(self.states) == 5

    def describe(self) -> str:
        """One line: the law and its gains."""
        gains = ", ".join(f"{k:.5g}" for k in self.K)
        return f"LQR state feedback V = -K [{', '.join(self.states)}], K = [{gains}]"

    def to_dict(self) -> dict:
        """The design as a controller file's ``[state_feedback]`` table."""
        table = {
            "plant": self.plant,
            "states": list(self.states),
            "K": [float(k) for k in self.K],
            "q": list(self.q),
            "r": self.r,
            "derivative_filter_hz": self.filter_hz,
            "derivative_filter_zeta": self.filter_zeta,
        }
        if self.integral:
            table["integral_limit"] = self.integral_limit
        return {"state_feedback": table}


def _linear_plant(plant: str, params: object | None) -> tuple[np.ndarray, np.ndarray]:
    """A and B of the plant's linear model, reordered to positions first."""
    order = [0, 2, 1, 3]  # the models' [x, xdot, angle, angledot] -> [x, angle, xdot, angledot]
    if plant == "seesaw":
        from pendulab.model.seesaw import linearize_seesaw

        ss = linearize_seesaw(params).ss  # type: ignore[arg-type]
    else:
        from pendulab.model.linear import linearize

        ss = linearize(params).ss  # type: ignore[arg-type]
    return ss.A[np.ix_(order, order)], ss.B[order]


def _state_model(plant: str, params: object | None, integral: bool) -> tuple[np.ndarray, np.ndarray]:
    """A and B on the feedback vector's order (:func:`state_names`), the integral of the angle appended."""
    A, B = _linear_plant(plant, params)
    if integral:
        A = np.block([[A, np.zeros((4, 1))], [np.eye(1, 4, 1), np.zeros((1, 1))]])  # d/dt integral = angle
        B = np.vstack([B, [[0.0]]])
    return A, B


def closed_loop_poles(design: StateFeedbackDesign, params: object | None = None) -> np.ndarray:
    """Eigenvalues of ``A - B K`` of the plant's continuous linear model with the design's K (e.g. a
    controller file's, which holds K only), sorted by real part.

    Examples
    --------
    >>> design = design_state_feedback("seesaw")
    >>> bool(np.allclose(closed_loop_poles(design), design.closed_loop_poles))
    True
    """
    A, B = _state_model(design.plant, params, design.integral)
    poles = np.linalg.eigvals(A - B @ np.asarray(design.K, dtype=float).reshape(1, -1))
    return poles[np.lexsort((poles.imag, poles.real))]


def design_state_feedback(
    plant: str = "seesaw",
    q: Sequence[float] | None = None,
    r: float | None = None,
    integral: bool | None = None,
    params: object | None = None,
) -> StateFeedbackDesign:
    """Design an LQR state feedback on the plant's linear model.

    Parameters
    ----------
    plant : {"pendulum", "seesaw"}
        Which plant.
    q : sequence of float, optional
        Diagonal of Q, one weight per entry of :func:`state_names` (4, or 5 with the integral).
        Default: Quanser's seesaw weights, or the pendulum block example's.
    r : float, optional
        Weight of the voltage (> 0).
    integral : bool, optional
        Add the integral of the angle to the state. Default: True for the seesaw, False for the pendulum;
        given ``q`` of length 5 implies True.
    params : PlantParameters or SeesawParameters, optional
        The plant's parameters (default preset).

    Returns
    -------
    StateFeedbackDesign

    Raises
    ------
    UserError
        An unknown plant, a Q of the wrong length or with a negative or non-finite entry, R not > 0.
    """
    if plant not in PLANTS:
        raise UserError(f"unknown plant {plant!r}; choose pendulum or seesaw")
    default_q, default_r, default_integral = DEFAULTS[plant]
    if integral is None:
        integral = len(q) == 5 if q is not None else default_integral
    n = 5 if integral else 4
    if q is None:
        q = default_q if len(default_q) == n else (*default_q[:4], 1000.0)[:n]
    q = tuple(float(v) for v in q)
    names = state_names(plant, integral)
    if len(q) != n:
        raise UserError(
            f"--q has {len(q)} weights but the state has {n} ({', '.join(names)}); give one weight per state "
            f"({'4 without' if integral else '5 with'} --integral)"
        )
    if not all(math.isfinite(v) and v >= 0 for v in q):
        raise UserError(f"--q weights must be finite and >= 0, got {','.join(f'{v:g}' for v in q)}")
    r = default_r if r is None else float(r)
    if not (math.isfinite(r) and r > 0):
        raise UserError(f"--r must be a finite number > 0 (the voltage's weight), got {r:g}")
    import control

    A, B = _state_model(plant, params, integral)
    try:
        K, _, poles = control.lqr(A, B, np.diag(q), r)
    except Exception as exc:  # an undetectable or unstabilizable weighting
        raise UserError(f"no LQR solution for Q = diag({', '.join(f'{v:g}' for v in q)}), R = {r:g}: {exc}; weight the angle and x") from None
    poles = np.asarray(poles)
    gains = tuple(float(k) for k in np.ravel(np.asarray(K)))
    return StateFeedbackDesign(plant, names, gains, poles[np.lexsort((poles.imag, poles.real))], q, r)


def _numbers(text: str, option: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise UserError(f"{option} {text!r} must be numbers separated by commas, e.g. {option} 1000,5000,0,0,2000") from None


def design_from_text(
    plant: str, q: str | None, r: str | None, integral: bool | None = None, params: object | None = None
) -> StateFeedbackDesign:
    """:func:`design_state_feedback` from typed text: ``q`` as ``"Q1,Q2,..."``, ``r`` one number (``pendulab lqr``
    and the GUI); None is the plant's default. Messages name ``--q`` and ``--r``.

    Examples
    --------
    >>> design_from_text("seesaw", "1000,5000,0,0,2000", "0.5") == design_state_feedback("seesaw")
    True
    >>> design_from_text("seesaw", "1000,5000", "0.5", integral=True)
    Traceback (most recent call last):
    pendulab.errors.UserError: --q has 2 weights but the state has 5 (x, theta, xdot, thetadot, theta_integral); give one weight per state (4 without --integral)
    """
    weights = None if q is None else _numbers(q, "--q")
    voltage = None if r is None else _numbers(r, "--r")
    if voltage is not None and len(voltage) != 1:
        raise UserError(f"--r {r!r} must be one number > 0")
    return design_state_feedback(plant, weights, None if voltage is None else voltage[0], integral, params)


def save_state_feedback_file(design: StateFeedbackDesign, path: str) -> None:
    """Write the design as a TOML controller file (``[state_feedback]``), atomically."""
    from pathlib import Path

    from pendulab.analysis.results import atomic_write

    def value(v: object) -> str:
        if isinstance(v, str):
            return json.dumps(v)  # a TOML basic string is a JSON string
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(float(v))  # type: ignore[arg-type]

    table = design.to_dict()["state_feedback"]
    lines = [f"# pendulab state feedback (LQR): V = -K [{', '.join(design.states)}]", "", "[state_feedback]"]
    lines += [f"{key} = {value(v)}" for key, v in table.items()]
    text = "\n".join(lines) + "\n"
    try:
        atomic_write(Path(path), lambda handle: handle.write(text.encode("utf-8")))
    except OSError as exc:
        raise UserError(f"cannot write controller file {path}: {exc.strerror or exc}; check the folder") from None


def load_state_feedback_file(path: str) -> StateFeedbackDesign:
    """Read a ``[state_feedback]`` controller file written by :func:`save_state_feedback_file`.

    Raises
    ------
    UserError
        The file is missing, not TOML, or its table is incomplete or inconsistent.
    """
    try:
        with open(path, "rb") as handle:
            text = handle.read().decode("utf-8")
    except OSError as exc:
        raise UserError(f"cannot read controller file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise UserError(f"controller file {path} is not a text file; give the TOML file 'pendulab lqr --out FILE' wrote") from None
    return state_feedback_from_text(text, str(path))


def state_feedback_from_text(text: str, name: str) -> StateFeedbackDesign:
    """A controller file's text (:func:`save_state_feedback_file`'s TOML) as a design; ``name`` names it in messages.

    Raises
    ------
    UserError
        Not TOML, no ``[state_feedback]`` table, or an incomplete or inconsistent one.
    """
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib  # type: ignore[no-redef]
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"controller file {name} is not valid TOML: {exc}") from None
    table = data.get("state_feedback")
    if not isinstance(table, dict):
        raise UserError(f"controller file {name} has no [state_feedback] table; write one with 'pendulab lqr --out FILE'")
    return design_from_table(table, f"controller file {name}")


def design_from_table(table: Any, source: str = "state feedback") -> StateFeedbackDesign:
    """A design from its ``[state_feedback]`` table (:meth:`StateFeedbackDesign.to_dict`).

    Raises
    ------
    UserError
        A missing entry, or states and gains that do not fit the plant.
    """
    if not isinstance(table, Mapping):
        raise UserError(f"{source} must be a table with plant, states and K")
    try:
        plant, K = table["plant"], tuple(float(k) for k in table["K"])
        states = tuple(str(s) for s in table["states"])
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(f"{source}: [state_feedback] needs plant, states and K ({exc})") from None
    if plant not in PLANTS or states != state_names(plant, len(states) == 5) or len(K) != len(states):
        raise UserError(f"{source}: states {list(states)} and K of length {len(K)} do not fit the {plant}")
    if not all(math.isfinite(k) for k in K):
        raise UserError(f"{source}: every gain in K must be finite")
    numbers = {}
    for key, default in (("derivative_filter_hz", FILTER_HZ), ("derivative_filter_zeta", FILTER_ZETA), ("integral_limit", INTEGRAL_LIMIT)):
        try:
            numbers[key] = float(table.get(key, default))
        except (TypeError, ValueError):
            raise UserError(f"{source}: {key} must be a number") from None
        if not (math.isfinite(numbers[key]) and numbers[key] > 0):
            raise UserError(f"{source}: {key} = {numbers[key]:g} must be a finite number > 0")
    return StateFeedbackDesign(
        plant, states, K, np.asarray([]), tuple(float(v) for v in table.get("q", ())), float(table.get("r", math.nan)),
        numbers["derivative_filter_hz"], numbers["derivative_filter_zeta"], numbers["integral_limit"],
    )


@dataclass(frozen=True)
class StateFeedbackRealization:
    """The state feedback with its derivative filters and integral as one discrete LTI block.

    Inputs ``u = [angle, x]`` (measured), output ``V``::

        z[k+1] = A z[k] + B u[k],   V[k] = C z[k] + D u[k]

    The states are the two derivative filters (two each, the cart's then the angle's) and, with the
    integral, the angle's integral last (forward Euler), limited to ``+/- integral_limit``.

    Attributes
    ----------
    A, B, C, D : numpy.ndarray
        Shapes (n, n), (n, 2), (1, n), (1, 2).
    integral_index : int
        1-based index of the integral state, 0 for none.
    integral_limit : float
        Limit of the integral state (rad s).
    h : float
        Sample period (s).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    integral_index: int
    integral_limit: float
    h: float

    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    def to_parameters(self) -> dict[str, float | int]:
        """Start values of the Controller FMU (its two-input form).

        The FMU's first input is the error ``e = r - Lp * alpha_measured``: with ``Lp = -1`` and ``r = 0``
        it is the measured angle itself; ``x_measured`` is the second input.
        """
        n = self.order
        out: dict[str, float | int] = {"n": n, "Lp": -1.0, "h": self.h}
        for i in range(n):
            for j in range(n):
                out[f"A[{i + 1},{j + 1}]"] = float(self.A[i, j])
        for i in range(n):
            out[f"B[{i + 1}]"] = float(self.B[i, 0])
            out[f"B_x[{i + 1}]"] = float(self.B[i, 1])
            out[f"C[{i + 1}]"] = float(self.C[0, i])
        out["D"], out["D_x"] = float(self.D[0, 0]), float(self.D[0, 1])
        out["integral_index"] = self.integral_index
        out["integral_limit"] = float(self.integral_limit)
        return out


def realize_state_feedback(design: StateFeedbackDesign, h: float = 1e-3, method: str = "tustin") -> StateFeedbackRealization:
    """Realize ``V = -K [x, angle, xdot, angledot(, integral)]`` with the velocities from 2nd-order
    derivative filters ``wf^2 s / (s^2 + 2 zeta wf s + wf^2)`` (Quanser's, 10 Hz and 0.9 by default),
    discretized at ``h`` by ``method`` ("tustin" or "zoh"), the integral by forward Euler.

    Examples
    --------
    >>> from pendulab.control.state_feedback import design_state_feedback, realize_state_feedback
    >>> block = realize_state_feedback(design_state_feedback("seesaw"))
    >>> block.order, block.integral_index
    (5, 5)
    """
    from pendulab.control.realization import _bilinear, _zero_order_hold

    if method not in ("tustin", "zoh"):
        raise UserError(f"unknown discretization method {method!r}; choose tustin or zoh")
    if not (math.isfinite(h) and h > 0):
        raise UserError(f"sample period h={h} must be a positive number of seconds")
    wf, zeta = 2 * math.pi * design.filter_hz, design.filter_zeta
    K = np.asarray(design.K, dtype=float)
    # One filter: z1' = z2, z2' = -wf^2 z1 - 2 zeta wf z2 + y; its derivative estimate is wf^2 z2.
    Af = np.array([[0.0, 1.0], [-wf * wf, -2 * zeta * wf]])
    A = np.zeros((4, 4))
    A[:2, :2] = A[2:, 2:] = Af
    B = np.zeros((4, 2))
    B[1, 1] = 1.0  # the cart's filter sees x (input 2)
    B[3, 0] = 1.0  # the angle's filter sees the angle (input 1)
    C = -np.array([[0.0, K[2] * wf * wf, 0.0, K[3] * wf * wf]])
    D = -np.array([[K[1], K[0]]])
    Ad, Bd, Cd, Dd = (_bilinear if method == "tustin" else _zero_order_hold)(A, B, C, D, h)
    if design.integral:
        Ad = np.block([[Ad, np.zeros((4, 1))], [np.zeros((1, 4)), np.ones((1, 1))]])
        Bd = np.vstack([Bd, [[h, 0.0]]])
        Cd = np.hstack([Cd, [[-K[4]]]])
    return StateFeedbackRealization(Ad, Bd, Cd, Dd, 5 if design.integral else 0, design.integral_limit, h)
