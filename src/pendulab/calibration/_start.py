"""Starting values for the fit from the logs themselves, whatever their shape.

From the lab's defaults the fit lands in a wrong minimum on a rig far from them (3 times the breakaway force, 5 times the slip drag). Any moving
cart's log shows drive and drag (:func:`drive_and_drag`), the breakaway force (:func:`breakaway_voltage`) and the slip region (:func:`slip_region`).

Examples
--------
>>> from pendulab.model.plant import PlantModel
>>> p = PlantParameters.preset("none", Beq=9.0, force_gain=0.7)
>>> t = np.arange(4000) * 1e-3
>>> V = 6.0 * np.sin(2 * np.pi * 0.5 * t)
>>> x = PlantModel().simulate(p, V, 1e-3)[:, 0]
>>> start = log_start([RampLog(np.r_[t, 4.0], np.r_[V, 0.0], x)], PlantParameters.preset("none"))
>>> round(start.force_gain, 1), round(start.Beq)
(0.7, 9)
"""

from __future__ import annotations

import contextlib
import math
from typing import Sequence

import numpy as np

from pendulab.calibration.extract import motor_constants
from pendulab.calibration.logs import RampLog
from pendulab.errors import ParameterError
from pendulab.exact import dot, lstsq, savgol
from pendulab.model.parameters import PlantParameters

#: Smoothing window for speed and acceleration (s).
SMOOTHING = 0.03
#: The fraction of moving samples (the fastest) that seeds the fit of the drive and the drag.
SEED_FRACTION = 0.2
#: ... and at least this share of the top speed (99.5th percentile): on strong slip drag a ramp's fastest fifth is still in the slip region.
SEED_SPEED_SHARE = 0.5


def _motion(logs: Sequence[RampLog], params: PlantParameters) -> tuple[np.ndarray, ...]:
    """Speed, acceleration and voltage (clipped to the amplifier's range) of the logs, all through the same smoothing filter, and whether the
    amplifier was below saturation; without each log's first and last smoothed samples.

    (Savitzky-Golay, cubic: linear, so the smoothed signals obey the raw ones' equation; smoothing only the acceleration would not, at a step.)
    """
    out: list[list[np.ndarray]] = [[], [], [], []]
    for log in logs:
        V = np.clip(log.V, -params.V_max, params.V_max)
        edge = max(5, int(round(SMOOTHING / log.period)))
        window = edge | 1  # odd
        if len(log) <= window:
            v = np.gradient(log.x, log.t)
            smoothed = (v, np.gradient(v, log.t), V)
        else:
            smoothed = tuple(savgol(y, window, 3, deriv=d, delta=log.period) for y, d in ((log.x, 1), (log.x, 2), (V, 0)))
        for column, values in zip(out, (*smoothed, np.abs(log.V) < 0.98 * params.V_max)):
            column.append(values[edge : len(log) - edge])
    return tuple(np.concatenate(column) for column in out)


def drive_and_drag(logs: Sequence[RampLog], params: PlantParameters) -> tuple[float, float] | None:
    """``(force_gain, Beq)`` from the fastest samples of the logs (None if too few move).

    A cart sliding fast feels no stick-slip friction: ``Mc*a = g*(K*V - b*v) - Beq*v`` (``K``, ``b``: force per volt, back-EMF damping at ``g = 1``).
    """
    K, b = motor_constants(params.with_values(force_gain=1.0))
    v, a, V, unsaturated = _motion(logs, params)
    A, y = np.column_stack([K * V - b * v, -v])[unsaturated], (params.lumped_cart_mass * a)[unsaturated]  # not where the amplifier saturates
    # Moving: faster than the encoder's quantization can fake through the smoothing window.
    speed = np.abs(A[:, 1])
    moving = speed > max(1e-3, 5.0 * float(params.q_x) / SMOOTHING)
    if np.count_nonzero(moving) < 50:
        return None
    A, y, speed = A[moving], y[moving], speed[moving]
    # Seeded by the fastest samples (past any slip region), grown to every sample the seed's answer explains: the accelerations that tell the drive
    # from the drag, but not the slip region's drag. A weak ridge towards params0 holds the scale where only cruising (a = 0, just the ratio) is seen.
    prior = np.array([params.force_gain, params.Beq])
    scale = np.sqrt(np.mean(A**2, axis=0)) + 1e-12
    use = speed >= max(np.quantile(speed, 1.0 - SEED_FRACTION), SEED_SPEED_SHARE * np.quantile(speed, 0.995))
    for _ in range(6):
        ridge = 1e-3 * np.count_nonzero(use)
        M = np.vstack([A[use] / scale, math.sqrt(ridge) * np.eye(2)])
        solution = lstsq(M, np.r_[y[use], math.sqrt(ridge) * prior * scale]) / scale
        residual = np.abs(dot(A, solution) - y)
        grown = residual <= 3.0 * (1.4826 * float(np.median(residual[use])) + 1e-9)  # within three robust spreads
        if np.array_equal(grown, use) or np.count_nonzero(grown) < 20:
            break
        use = grown
    gain, Beq = (float(s) for s in solution)
    return (gain, max(Beq, 0.0)) if math.isfinite(gain) and math.isfinite(Beq) and gain > 0 else None


def breakaway_bounds(logs: Sequence[RampLog], step: float) -> tuple[float | None, float | None]:
    """``(held, broke)``: the largest voltage the cart held through a rest, and the smallest at which it broke away.

    A stuck cart feels no back-EMF, so ``F1`` lies between ``gain K held`` and ``gain K broke``. Where the cart broke away, the voltage reached just
    before it moved is an upper bound whether it rose slowly or jumped there. None where the logs show no such rest.
    """
    from pendulab.calibration._polish import rest_samples, rests

    held, broke = [], []
    for log in logs:
        w = rest_samples(log.period)
        for first, stop in rests(log.x, step, max(step / math.sqrt(12), 1e-6), log.period):  # noise: the encoder step's quantization
            inside = np.abs(log.V[first + w : max(first + w, stop - 2 * w)])
            if inside.size:
                held.append(float(np.max(inside)))
            if stop < len(log) - 1:
                broke.append(float(np.max(np.abs(log.V[max(first, stop - 2 * w) : stop + 1]))))
    lower = max(held) if held else None
    return lower, min((u for u in broke if lower is None or u >= lower), default=None)


def breakaway_voltage(logs: Sequence[RampLog], step: float) -> float | None:
    """The voltage of the breakaway force ``F1`` (V at rest), between :func:`breakaway_bounds` (None if none)."""
    lower, upper = breakaway_bounds(logs, step)
    if upper is not None:
        return upper if lower is None else 0.5 * (lower + upper)
    return 1.1 * lower if lower is not None and lower > 0.05 else None  # held only: a little above it


def log_start(logs: Sequence[RampLog], params0: PlantParameters) -> PlantParameters:
    """``params0`` with ``force_gain``, ``Beq`` and ``F1`` (and ``F2`` kept in its ratio to ``F1``) from the logs, and ``B`` and ``v2`` where they show the slip
    region (:func:`slip_region`; ``F2`` then at least the force the cart slid under, :func:`slipping_force`).

    What the logs cannot show keeps ``params0``'s value. Logs of the cart alone (the fit asks only for those).
    """
    drive = drive_and_drag(logs, params0)
    values: dict[str, float] = {} if drive is None else {"force_gain": drive[0], "Beq": drive[1]}
    gain = values.get("force_gain", params0.force_gain)
    V1 = breakaway_voltage(logs, float(params0.q_x))
    if V1 is not None:
        K, _ = motor_constants(params0.with_values(force_gain=1.0))
        F1 = gain * K * V1
        # F2 in its ratio to F1, at least F1, not at least params0's: from a ramp extraction that read a triangle wave's F1 as 4.6 N (true 0.5),
        # F2 stayed there (true 0.9) and the fit ended 7.7 encoder steps off with F2 45 times too large.
        values.update(F1=F1, F2=F1 * max(params0.F2 / max(params0.F1, 1e-9), 1.0))
    if drive is not None:
        driven = params0.with_values(force_gain=gain, Beq=values["Beq"])
        slip = slip_region(logs, driven)
        if slip is not None:
            values.update(B=slip[0], v2=slip[1], v1=min(params0.v1, 0.5 * slip[1]))
            pushed = slipping_force(logs, driven, slip[0], slip[1])
            if pushed is not None:
                values["F2"] = max(values.get("F2", params0.F2), pushed)
    start = params0
    for name, value in values.items():  # an estimate outside the plant's range (a log it misreads) is left out
        with contextlib.suppress(ParameterError):
            start = start.with_values(**{name: value})
    return start


def _friction_needed(logs: Sequence[RampLog], params: PlantParameters) -> tuple[np.ndarray, ...]:
    """Over the logs: ``|v|``, the friction ``R`` each sample needed (:func:`slip_region`; along ``v``), ``|gain*(K*V - b*v)|`` and ``|Mc*a|``."""
    K, b = motor_constants(params.with_values(force_gain=1.0))
    v, a, V, _ = _motion(logs, params)
    motor, inertia = params.force_gain * (K * V - b * v), params.lumped_cart_mass * a
    return np.abs(v), (motor - params.Beq * v - inertia) * np.sign(v), np.abs(motor), np.abs(inertia)


def _sliding_speed(params: PlantParameters) -> float:
    """The speed (m/s) above which a sample slides for the slip region's reading: faster than encoder quantization can fake through the smoothing."""
    return max(2e-3, 5.0 * float(params.q_x) / SMOOTHING)


def slipping_force(logs: Sequence[RampLog], params: PlantParameters, B: float, v2: float) -> float | None:
    """The largest motor force (its 90th percentile) the cart slid under in the slip region (drag ``B`` below ``v2``): a lower bound of ``F2``, since
    the slip region ends where the motor's force passes it. None where fewer than 20 samples slid there."""
    v, R, motor, inertia = _friction_needed(logs, params)
    # Sliding steadily (the inertia a tenth of the drive at most) with the slip region's drag, within a factor 2.
    slipping = (v > _sliding_speed(params)) & (v < v2) & (R > 0.5 * B * v) & (R < 2.0 * B * v) & (inertia <= 0.1 * motor)
    return float(np.quantile(motor[slipping], 0.9)) if np.count_nonzero(slipping) >= 20 else None


#: Speed bands (quantiles of the moving samples) in which the slip drag is read.
SLIP_BANDS = 20


def slip_region(logs: Sequence[RampLog], params: PlantParameters) -> tuple[float, float] | None:
    """``(B, v2)``, the slip region's drag and end speed, read off the logs (None if they show none).

    With the drive and ``Beq`` of ``params`` (:func:`drive_and_drag`), the friction each sample needed is ``R = gain*(K*V - b*v) - Beq*v - Mc*a``: the
    motor's force while stuck, ``B*v`` in the slip region, 0 beyond. Over bands of speed ``R/v`` is ``B`` up to ``v2``, 0 above: ``B`` is its median
    over the bands clearly above 0, ``v2`` the speed best splitting the samples of the last of those and the next band into drag ``B`` and none. A log
    that never leaves the slip region (or never enters it): None.
    """
    _, b = motor_constants(params.with_values(force_gain=1.0))
    v, R, *_ = _friction_needed(logs, params)
    moving = v > _sliding_speed(params)
    if np.count_nonzero(moving) < 10 * SLIP_BANDS:
        return None
    v, R = v[moving], R[moving]
    edges = np.quantile(v, np.linspace(0.0, 1.0, SLIP_BANDS + 1))
    band = np.clip(np.searchsorted(edges, v, side="right") - 1, 0, SLIP_BANDS - 1)
    ratio = np.array([np.median(R[band == k] / v[band == k]) for k in range(SLIP_BANDS)])
    # Clearly above 0: a fifth of the drag the cart feels beyond the slip region, and a fifth of the largest band.
    slip = ratio > max(0.2 * (params.Beq + params.force_gain * b), 0.2 * float(np.max(ratio)))
    if not np.any(slip) or np.all(slip):
        return None
    B = float(np.median(ratio[slip]))
    # v2: in the last slip band and the next, the speed best splitting the samples with drag B (R/v above B/2) from those beyond (fewest misplaced).
    last = int(np.flatnonzero(slip)[-1])
    near = (band >= last) & (band <= last + 1)
    order = np.argsort(v[near], kind="stable")
    speeds, slipping = v[near][order], (R[near] / v[near] > 0.5 * B)[order]
    wrong = np.r_[0, np.cumsum(~slipping)] + np.r_[np.cumsum(slipping[::-1])[::-1], 0]
    k = int(np.argmin(wrong))  # the split falls before sample k: v2 halfway between its neighbours
    return B, 0.5 * float(speeds[max(k - 1, 0)] + speeds[min(k, speeds.size - 1)])
