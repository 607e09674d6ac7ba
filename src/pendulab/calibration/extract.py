"""Friction vector ``[F1, v1, F2, v2, B]`` from a ramp-test log (SPEC §8).

The log is cut into pushes by its voltage alone, so logs of the real rig, of the virtual rig and of other tools are read the same way: a *push* starts
where the voltage leaves 0 as a ramp (``V = rate * (t - t0)``) and ends where it returns to 0 (the *release*). A ramp slower than 10 V/s is a
breakaway ramp, a steeper one an ``F2`` probe (see :mod:`pendulab.calibration.ramp`).

What is measured, per push
--------------------------
``F1``
    Motor force when the cart starts to move on a slow ramp: ``F1 = K * |V|`` (``K``: :func:`motor_constants`) at the last sample before it moves.
``v2``, ``B``, ``v1`` (and ``Beq``)
    After a release (0 V) the speed decays in three exponentials: above ``v2`` with ``(Beq + b)/Mc`` (``b`` the back-EMF damping), between ``v2`` and
    ``v1`` with ``(Beq + b + B)/Mc`` (the strong drag), and below ``v1``, stuck, with ``Beq/Mc``. Their closed form is fitted to the logged positions
    (least squares, averaging encoder steps): ``v2`` is the strong-drag phase's top speed, ``B`` from its decay, ``v1`` where the cart sticks.
``F2``
    On a steep probe the force outruns the speed: the cart leaves the drag regime when the motor force passes ``F2``. The probe is simulated (the rest
    as measured) for candidate ``F2``, the best match to the logged positions kept; one that left the drag regime by its speed gives no ``F2``.

Mass ratio
----------
The ramp test runs with the pendulum removed; its weight presses the cart onto its track and gear, and the stick-slip forces grow with that normal
force: ``F1`` and ``F2`` are multiplied by :func:`mass_ratio` (1.40 for the long pendulum on the IP02), not ``v1``, ``v2``, ``B``.

All estimates are averaged over the iterations (both directions); the spread is their standard deviation.

Examples
--------
>>> from pendulab.calibration.rig import VirtualRig
>>> from pendulab.calibration.ramp import run_ramp_test
>>> with VirtualRig(friction=(2.0, 0.004, 3.6, 0.06, 25.0)) as rig:
...     log = run_ramp_test(rig, iterations=1)
>>> est = extract_friction(log)
>>> bool(abs(est.friction[0] - 2.0) < 0.1), bool(abs(est.friction[2] - 3.6) < 0.2)
(True, True)
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.optimize import OptimizeWarning, least_squares

from pendulab import exact
from pendulab.calibration.files import UNITS, Calibration
from pendulab.calibration.logs import RampLog, encoder_step
from pendulab.calibration.rig import NO_PENDULUM
from pendulab.errors import CalibrationError
from pendulab.model.parameters import FRICTION_NAMES, PlantParameters

#: Ramps steeper than this (V/s) are F2 probes, slower ones breakaway ramps.
PROBE_RATE_THRESHOLD = 10.0
_ZERO = 1e-6  # |V| below this is "motor off"


def mass_ratio(params: PlantParameters) -> float:
    """``(M_cart + Mp) / M_cart``: how much the pendulum's weight raises the cart's normal force.

    Examples
    --------
    >>> round(mass_ratio(PlantParameters.preset("long")), 3)
    1.404
    >>> mass_ratio(PlantParameters.preset("none"))
    1.0
    """
    return (params.M_cart + params.Mp) / params.M_cart


def motor_constants(params: PlantParameters) -> tuple[float, float]:
    """``(K, b)``: motor force per volt at rest (N/V) and back-EMF damping (N·s/m), from the CasADi model.

    ``F_motor = K*V - b*xdot`` below the amplifier limits.
    """
    import casadi as ca

    from pendulab.model.plant import plant_equations

    state, V = ca.SX.sym("s", 4), ca.SX.sym("V")
    _, signals = plant_equations(state, V, dict(zip(params.names(), params.with_values(I_max=0.0).as_vector())), 0.0)
    f = ca.Function("motor_force", [state, V], [signals["F_motor"]])
    return float(f([0, 0, 0, 0], 1.0)), -float(f([0, 1.0, 0, 0], 0.0))  # K: 1 V at rest; b: 1 m/s at 0 V


@dataclass(frozen=True)
class FrictionEstimate:
    """The extracted friction vector.

    Attributes
    ----------
    friction : tuple
        ``(F1, v1, F2, v2, B)`` for the model, forces scaled by ``mass_ratio``.
    measured : tuple
        As measured with the pendulum removed (unscaled).
    spread : dict
        Standard deviation of each entry over the pushes (forces scaled like ``friction``).
    counts : dict
        How many pushes measured each entry (0: kept from the nominal parameters, see ``notes``).
    Beq : float or None
        The cart's viscous damping seen in the coasting phases (N·s/m).
    """

    friction: tuple[float, float, float, float, float]
    measured: tuple[float, float, float, float, float]
    spread: dict[str, float]
    counts: dict[str, int]
    mass_ratio: float
    Beq: float | None
    pushes: int  # pushes whose cart broke away
    notes: tuple[str, ...] = field(default=())

    def to_calibration(self, **metadata: Any) -> Calibration:
        """A :class:`Calibration` holding ``friction`` and this estimate's measurement record."""
        return Calibration(friction=self.friction, metadata={
            "method": "ramp test (SPEC 8)",
            "mass_ratio": self.mass_ratio,
            "measured_friction": dict(zip(FRICTION_NAMES, self.measured)),
            "spread": self.spread,
            "counts": self.counts,
            "Beq_ramp": self.Beq,
            "pushes": self.pushes,
            "notes": list(self.notes),
            **metadata,
        })

    def summary(self) -> str:
        lines = []
        for name, value, measured in zip(FRICTION_NAMES, self.friction, self.measured):
            scaled = f" (measured {measured:.4g})" if name in ("F1", "F2") and self.mass_ratio != 1 else ""
            lines.append(f"{name} = {value:.4g} ± {self.spread[name]:.2g} {UNITS[name]}{scaled}  [n={self.counts[name]}]")
        return "\n".join(lines)


# ---------------------------------------------------------------------- segmentation
@dataclass(frozen=True)
class _Push:
    start: int  # first sample of the ramp (V != 0)
    release: int  # first sample with V == 0 again (len(V) if never)
    end: int  # next push's start or the end of the log
    rate: float  # V/s, signed


def _find_pushes(log: RampLog) -> list[_Push]:
    V, dt = log.V, log.period
    off = np.abs(V) <= _ZERO
    pushes: list[_Push] = []
    for a in np.flatnonzero(off[:-1] & ~off[1:]) + 1:  # where V leaves 0
        first = V[a]
        # The ramp-from-zero signature: V[a+j] = (j+1) V[a] over the first three samples.
        expected = first * np.arange(1, 4)
        if len(V) - a < 3 or not np.all(np.abs(V[a : a + 3] - expected) <= 0.02 * np.abs(expected) + 1e-9):
            continue
        after = np.flatnonzero(off[a:])
        release = a + int(after[0]) if after.size else len(V)
        pushes.append(_Push(int(a), int(release), len(V), float(first / dt)))
    return [replace(p, end=following.start) for p, following in zip(pushes, pushes[1:])] + pushes[-1:]  # the last ends with the log


def _onset_voltage(t: np.ndarray, V: np.ndarray, x: np.ndarray, x_rest: float, direction: int, j: int, k: int) -> float:
    """Voltage when the cart started to move.

    The first encoder step shows only after the cart has crept half a step; the displacement grows like ``c (t - t0)^2`` from the onset ``t0``
    (constant force excess or force ramp), so a parabola fitted to the first steps dates the onset. Falls back to the last sample at rest.
    """
    lo = max(0, j - 20)
    tt, d = t[lo : k + 1], direction * (x[lo : k + 1] - x_rest)
    if len(tt) < 5 or d[-1] <= 0:
        return float(V[j])

    def residual(theta: np.ndarray) -> np.ndarray:
        c, t0 = theta
        return c * np.clip(tt - t0, 0, None) ** 2 - d

    span = float(tt[-1] - tt[0])
    c0 = d[-1] / max(float(tt[-1] - t[j]), 1e-3) ** 2
    try:
        fit = least_squares(residual, [c0, float(t[j])], bounds=([0, tt[0] - span], [np.inf, tt[-1]]), x_scale=[c0, 1e-3])
    except ValueError:
        return float(V[j])
    t0 = float(fit.x[1])
    return float(np.interp(t0, t, V)) if t[j] - 0.1 <= t0 <= t[k] else float(V[j])


# ---------------------------------------------------------------------- coasting (release) fit
def _coast_distance(tau: np.ndarray, u0: float, lam0: float, lam_s: float, lam_c: float, v2: float, v1: float) -> np.ndarray:
    """Distance covered after release at speed ``u0``: free (``lam0``), drag (``lam_s``), stuck (``lam_c``)."""
    u2 = min(u0, v2)
    T2 = math.log(u0 / u2) / lam0
    u1 = min(u2, v1)
    T1 = T2 + math.log(u2 / u1) / lam_s
    D2 = (u0 - u2) / lam0
    D1 = D2 + (u2 - u1) / lam_s
    return np.where(
        tau < T2,
        u0 / lam0 * (1 - exact.exp(-lam0 * tau)),
        np.where(
            tau < T1,
            D2 + u2 / lam_s * (1 - exact.exp(-lam_s * np.clip(tau - T2, 0, None))),
            D1 + u1 / lam_c * (1 - exact.exp(-lam_c * np.clip(tau - T1, 0, None))),
        ),
    )


def _fit_coast(t: np.ndarray, x: np.ndarray, direction: int, u_guess: float, Mc: float, b: float, Beq0: float):
    """Fit ``[x0, u0, Beq, B, v2, v1]`` of the coasting motion; returns (values or None, rms)."""
    tau = t - t[0]

    def residual(theta: np.ndarray) -> np.ndarray:
        x0, u0, Beq, B, v2, v1 = theta
        lam0, lam_s, lam_c = (Beq + b) / Mc, (Beq + b + B) / Mc, Beq / Mc
        return x0 + direction * _coast_distance(tau, u0, lam0, lam_s, lam_c, v2, v1) - x

    lower = [x[0] - 0.01, 1e-4, 0.05, 0.0, 1e-4, 1e-5]
    upper = [x[0] + 0.01, 5.0, 50.0, 500.0, 2.0, 1.0]
    best = None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", (OptimizeWarning, RuntimeWarning))
        for v2 in (0.02, 0.05, 0.1):
            theta0 = np.clip([x[0], max(u_guess, 2e-4), Beq0, 20.0, v2, v2 / 10], lower, upper)
            try:
                fit = least_squares(residual, theta0, bounds=(lower, upper), x_scale=[1e-3, 0.1, 1.0, 10.0, 0.01, 0.001], max_nfev=400)
            except (ValueError, FloatingPointError):
                continue
            if best is None or fit.cost < best.cost:
                best = fit
    return (None, math.inf) if best is None else (best.x, float(np.sqrt(2 * best.cost / len(t))))


# ---------------------------------------------------------------------- F2 probe fit
def _fit_F2(log: RampLog, lo: int, hi: int, params: PlantParameters, F_low: float, F_high: float) -> float | None:
    """Best ``F2`` in ``[F_low, F_high]`` for samples ``lo:hi`` from rest, on a coarse-to-fine grid; ``None`` if barely better than ``F_high``."""
    from pendulab.calibration._replay import replay
    from pendulab.calibration.fit import DEFAULT_FIT

    if hi - lo < 20 or F_high <= F_low:
        return None
    x = log.x[lo:hi]
    x0 = np.array([x[0], 0.0, 0.0, 0.0])

    def costs(candidates: np.ndarray) -> np.ndarray:
        # The fit's replay (its parameters free: the compiled library the fit uses, no other to build).
        states = replay([params.with_values(F2=float(F2)) for F2 in candidates], log.V[lo : hi - 1], log.t[lo : hi - 1], x0, free=DEFAULT_FIT)
        return np.sum((states[:, :, 0] - x[None, 1:]) ** 2, axis=1)

    left, right = F_low, F_high
    reference = None
    for _ in range(3):
        grid = np.linspace(left, right, 16)
        J = costs(grid)
        if reference is None:
            reference = float(J[-1])
        k = int(np.argmin(J))
        # The cost has plateaus (the voltage is held per sample): centre on the plateau of the minimum.
        flat = np.flatnonzero(J <= J[k] * (1 + 1e-6) + 1e-18)
        best = 0.5 * (grid[flat[0]] + grid[flat[-1]])
        step = grid[1] - grid[0]
        left, right = max(F_low, grid[flat[0]] - step), min(F_high, grid[flat[-1]] + step)
    return None if J[k] > 0.25 * reference or best >= 0.98 * F_high else float(best)


# ---------------------------------------------------------------------- main entry
def extract_friction(log: RampLog, mass_ratio: float = 1.0, *, params: PlantParameters | None = None) -> FrictionEstimate:
    """Extract the friction vector from a ramp-test log (see the module docstring).

    Parameters
    ----------
    log : RampLog
        A log of :func:`~pendulab.calibration.ramp.run_ramp_test` (or any log with slow voltage ramps from rest and releases to 0 V).
    mass_ratio : float
        Factor on ``F1`` and ``F2`` for the pendulum's weight (:func:`mass_ratio`); 1 keeps the vector as measured with the pendulum removed.
    params : PlantParameters, optional
        Nominal cart parameters (motor constants, lumped mass), whose friction fills what the log cannot show (``notes``); default: IP02 cart alone.

    Raises
    ------
    CalibrationError
        The log holds no ramp with a breakaway (too short, the cart never moved, no ramps).
    """
    if not (isinstance(mass_ratio, (int, float)) and math.isfinite(mass_ratio) and mass_ratio > 0):
        raise CalibrationError(f"mass ratio {mass_ratio!r} must be a positive number")
    params = (params or PlantParameters.preset("none")).with_values(**NO_PENDULUM)
    K, b = motor_constants(params)
    where = f"log {log.source}" if log.source else "log"
    t, V, x, dt = log.t, log.V, log.x, log.period
    q = encoder_step(x)
    pushes = _find_pushes(log)
    ramps = [p for p in pushes if abs(p.rate) < PROBE_RATE_THRESHOLD]
    if not ramps:
        raise CalibrationError(f"{where} ({log.duration:.3g} s) contains no voltage ramp from 0 V; record it with 'pendulab calibrate' "
                               "(slow ramps until the cart breaks away)")

    notes: list[str] = []
    estimates: list[dict[str, float | None]] = []  # what each push measured (None where it could not tell)
    onsets: dict[int, int] = {}  # push start -> last sample at rest before the breakaway
    w = max(2, int(round(0.02 / dt)))  # 20 ms
    for push in pushes:
        direction = 1 if push.rate > 0 else -1
        rest = x[max(0, push.start - 50) : push.start + 1]
        noise = float(np.std(rest - np.median(rest)))
        threshold = max(3 * q, 6 * noise, 1e-6)
        # Breakaway: the cart covers `threshold` within 20 ms (a slow glide of a not quite stopped cart does not), in the direction of the voltage.
        lo, hi = max(push.start - w, 0), push.release
        if hi - lo <= w:
            continue
        beyond = np.flatnonzero(direction * (x[lo + w : hi] - x[lo : hi - w]) >= threshold)
        if not beyond.size:
            continue  # the cart did not break away during this push
        k = lo + w + int(beyond[0])
        x_rest = float(x[k - w])
        unmoved = np.flatnonzero(np.abs(x[k - w : k] - x_rest) <= max(0.5 * q, 3 * noise, 1e-7))
        j = k - w + int(unmoved[-1]) if unmoved.size else k - w
        # A cart that moved only after the release did not break away on the ramp itself.
        F1 = K * abs(_onset_voltage(t, V, x, x_rest, direction, j, k)) if push in ramps and j < push.release - 1 else None
        onsets[push.start] = j
        values: dict[str, float | None] = {"v1": None, "v2": None, "B": None, "Beq": None}
        r = push.release
        powered = np.flatnonzero(np.abs(V[r:]) > _ZERO)
        e = r + int(powered[0]) if powered.size else len(V)
        if e - r >= 50:
            pre = slice(max(push.start, r - 20), r + 1)
            u_guess = abs(np.polyfit(t[pre] - t[r], x[pre], 1)[0]) if r - pre.start >= 3 else 0.0
            theta, rms = _fit_coast(t[r:e], x[r:e], direction, u_guess, params.lumped_cart_mass, b, params.Beq)
            if theta is not None and rms <= max(3 * q, 6 * noise, 2e-6):
                _, u0, Beq, B, v2, v1 = (float(v) for v in theta)
                values["Beq"] = Beq
                if v2 < 0.95 * u0:  # the cart coasted freely first: the drag phase started at v2
                    values.update(v2=v2, B=B, v1=v1 if v1 < 0.95 * v2 else None)
        estimates.append({"F1": F1, **values})
    if not any(e["F1"] is not None for e in estimates):
        raise CalibrationError(f"{where} ({log.duration:.3g} s) contains no breakaway: the cart never started moving on a ramp from rest; "
                               "the log is too short or the ramps stop too early")

    measured: dict[str, float] = {}
    spread: dict[str, float] = {}
    counts: dict[str, int] = {}
    for name in ("F1", "v1", "v2", "B", "Beq"):
        values_ = [e[name] for e in estimates if e[name] is not None]
        counts[name] = len(values_)
        if values_:
            measured[name], spread[name] = float(np.mean(values_)), (float(np.std(values_, ddof=1)) if len(values_) > 1 else 0.0)
        elif name != "Beq":
            measured[name], spread[name] = getattr(params, name), 0.0
            notes.append(f"{name} not observed (no coasting phase showed it); kept the nominal {measured[name]:g}")
    measured["v1"] = min(measured["v1"], measured["v2"])

    # F2: pushes simulated with the rest as measured. A slow ramp shows it only where the drag regime ends by force first: F2 < v2 (B + Beq).
    fit_params = params.with_values(**{n: measured[n] for n in ("F1", "v1", "v2", "B")}, Beq=measured.get("Beq", params.Beq), F2=measured["F1"])
    F2_crit = fit_params.v2 * (fit_params.B + fit_params.Beq)
    found: dict[str, list[float]] = {"ramp": [], "probe": []}
    for push in pushes:
        kind = "ramp" if abs(push.rate) < PROBE_RATE_THRESHOLD else "probe"
        hi = min(push.release + 40, push.end)
        if kind == "ramp":
            if push.start not in onsets or F2_crit <= measured["F1"]:
                continue
            lo = max(push.start, onsets[push.start] - 50)
            # Once the cart is faster than v2 the drag is gone whatever F2 is: nothing more to learn.
            fast = np.flatnonzero(np.abs(x[lo + w : hi] - x[lo : hi - w]) / (w * dt) > 1.2 * measured["v2"])  # the speed
            hi = lo + w + int(fast[0]) + 50 if fast.size else hi
            F_high = 1.1 * F2_crit
        else:  # a probe: up to a little above the largest force it applied (V leaves 0 at its start, so release > start)
            lo = max(0, push.start - 20)
            F_high = 1.05 * (K * float(np.max(np.abs(V[push.start : push.release]))))
        F2 = _fit_F2(log, lo, hi, fit_params, measured["F1"], F_high)
        if F2 is not None:
            found[kind].append(F2)
    # A slow ramp resolves F2 far better than a probe (whose force jumps by rate*dt per sample).
    F2_values = found["ramp"] or found["probe"]
    counts["F2"] = len(F2_values)
    if F2_values:
        measured["F2"], spread["F2"] = float(np.mean(F2_values)), (float(np.std(F2_values, ddof=1)) if len(F2_values) > 1 else 0.0)
    else:
        measured["F2"], spread["F2"] = max(params.F2, measured["F1"]), 0.0
        notes.append(f"F2 not observed (no probe left the drag regime by force); kept {measured['F2']:g} N as measured (>= F1)")

    scale = {"F1": mass_ratio, "F2": mass_ratio}
    if log.interrupted:
        notes.append("the ramp test was interrupted; the estimate uses the iterations measured until then")
    return FrictionEstimate(
        friction=tuple(measured[n] * scale.get(n, 1.0) for n in FRICTION_NAMES),  # type: ignore[arg-type]
        measured=tuple(measured[n] for n in FRICTION_NAMES),  # type: ignore[arg-type]
        spread={**{n: spread[n] * scale.get(n, 1.0) for n in FRICTION_NAMES}, "Beq": spread.get("Beq", 0.0)},
        counts=counts,
        mass_ratio=float(mass_ratio),
        Beq=measured.get("Beq"),
        pushes=len(estimates),
        notes=tuple(notes),
    )
