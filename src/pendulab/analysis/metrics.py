"""Response metrics of a poke run (SPEC §7), measured from the poke on.

The response to a poke is a damped oscillation of the angle about its final value. The metrics are
read from it the way a student reads them off a plot, but robustly: the signal may be the true angle
of a simulation or the rig's quantized (staircase) encoder angle ``alpha_measured``.

How the signal is read
----------------------
* The *initial value* is the angle just before the poke (median of the last 0.1 s, so a quantized
  signal toggling between two steps gives a sensible value).
* The *final value* is the mean of the last 10 % of the record after the poke; it is reported
  only when the angle settled (stayed in the settling band for at least that last 10 %).
* The deviation from the final value is split into *lobes* (swings to one side) with a hysteresis
  of one encoder step, so the staircase of a quantized signal never creates spurious swings.
  The extremum of a lobe is taken at the middle of its plateau (a quantized peak is flat).
* The *first peak* is the extremum of the first swing away from the initial value that reaches a
  tenth of the whole response; the overshoot is the next swing past the final value.
* The damped frequency comes from the crossings of the final value between lobes, fitted as
  ``c_k = c_0 + k * pi / omega_d + (-1)^k * beta``; the ``beta`` term absorbs the alternating
  offset that quantization gives to up- and down-going crossings.

Values that cannot be determined are ``None`` (JSON ``null``), never NaN.

Examples
--------
>>> import numpy as np
>>> t = np.arange(0.0, 6.0, 1e-3)
>>> tau = np.clip(t - 1.0, 0.0, None)
>>> alpha = 0.05 * np.exp(-2.0 * tau) * np.sin(8.0 * tau)
>>> m = compute_metrics(t, alpha, poke_start=1.0)
>>> round(m["natural_frequency_rad_s"], 3), m["stable"]
(8.0, True)
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from pendulab.errors import UserError

METRIC_KEYS = (
    "natural_frequency_rad_s",
    "peak_time_s",
    "overshoot_percent",
    "settling_time_s",
    "final_value_rad",
    "cart_speed_change_m_s",
    "safety_cut_time_s",
    "stable",
    "limit_cycle_amplitude_rad",
    "limit_cycle_frequency_rad_s",
)

#: An angle beyond this (rad) means the pendulum has fallen: the response is not bounded.
FALLEN_ANGLE = math.pi / 2
#: Fraction of the record after the poke over which the final value is averaged (and for which the
#: angle must stay inside the settling band for the response to count as settled).
TAIL_FRACTION = 0.10
#: Settling band relative to the first peak (SPEC §7: 2 %).
SETTLING_FRACTION = 0.02
#: A limit cycle: at least this many swings in the analysed tail, none decaying below this fraction of
#: the tail's largest, and an amplitude of at least two encoder steps (one step is the staircase).
LIMIT_CYCLE_SWINGS = 4
LIMIT_CYCLE_STEADINESS = 0.5
#: Part of the record (from its end) where a limit cycle is looked for.
LIMIT_CYCLE_TAIL = 0.5


class _Lobe(NamedTuple):
    """One swing of the deviation to one side of the reference (a tuple: a long limit cycle has hundreds)."""

    sign: int
    start: int  # first index with |dev| > h on this side
    end: int  # last index before the deviation leaves this side (exclusive of the next lobe)
    peak_index: int  # an index of the extremum (for its value)
    peak_time: float  # middle of the extremum's plateau
    closed: bool  # the signal turned back by more than the hysteresis after the extremum


def compute_metrics(
    t: Any,
    alpha: Any,
    *,
    poke_start: float,
    q_alpha: float = 0.001,
    xdot: Any = None,
    safety_cut_time: float | None = None,
) -> dict[str, Any]:
    """Metrics of the angle's response to a poke, with exactly the keys of SPEC §7.

    Parameters
    ----------
    t : array_like
        Sample times (s), strictly increasing.
    alpha : array_like
        Pendulum angle from upright (rad): the true angle when available, or the quantized
        ``alpha_measured`` (the rig gives only that).
    poke_start : float
        Time the poke starts (s); every metric is measured from it.
    q_alpha : float
        Angle encoder step (rad). It sets the hysteresis against staircase artefacts and the
        smallest settling band; 0 for an unquantized signal.
    xdot : array_like, optional
        Cart speed (m/s) at the same times, for ``cart_speed_change_m_s``.
    safety_cut_time : float, optional
        Time the supervisor cut the motor (s), or None. After a cut the response is only read up
        to the cut, and the run is not stable.

    Returns
    -------
    dict
        ``natural_frequency_rad_s`` damped oscillation frequency; ``peak_time_s`` poke start to
        the first peak of ``|alpha - initial|``; ``overshoot_percent`` first swing back past the
        final value relative to the first peak (0 when the response settles without crossing);
        ``settling_time_s`` poke start until the angle stays within
        ``max(2 % of the first peak, q_alpha)`` of the final value (and stays there for at least
        the last 10 % of the record); ``final_value_rad`` (mean of the last 10 %; None after a cut or a fall);
        ``cart_speed_change_m_s`` the mean cart speed over the last second (up to a cut) minus its mean
        over the half second before the poke (a mean over a window is the net movement over it: robust
        to stick-slip and quantization);
        ``safety_cut_time_s``; ``stable`` (no cut, bounded, and settled or not growing). Undeterminable values are
        None.

    Raises
    ------
    UserError
        Arrays of different lengths, too short, non-increasing times, or a poke outside the record.
    """
    t, alpha = _as_1d("t", t), _as_1d("alpha", alpha)
    if t.size != alpha.size:
        raise UserError(f"t has {t.size} samples but alpha has {alpha.size}; give both at the same times")
    if t.size < 3:
        raise UserError(f"the record has {t.size} samples; metrics need at least 3")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise UserError("the time column is not strictly increasing and finite; give samples in time order")
    poke_start = float(poke_start)
    if not math.isfinite(poke_start) or not t[0] <= poke_start < t[-1]:
        raise UserError(
            f"the poke starts at t={poke_start:g} s, outside the record [{t[0]:g}, {t[-1]:g}] s; "
            "set the poke start inside the run (or lengthen the run)"
        )
    q = float(q_alpha)
    if not math.isfinite(q) or q < 0:
        raise UserError(f"q_alpha={q_alpha} must be a finite step >= 0 rad")
    cut = None if safety_cut_time is None else float(safety_cut_time)
    if cut is not None and not math.isfinite(cut):
        raise UserError(f"safety_cut_time={safety_cut_time} is not finite; give the cut time in s or None")

    metrics: dict[str, Any] = {key: None for key in METRIC_KEYS}
    metrics["safety_cut_time_s"] = cut
    if xdot is not None:
        metrics["cart_speed_change_m_s"] = _speed_change(t, _as_1d("xdot", xdot), poke_start, cut)

    initial = _initial_value(t, alpha, poke_start)

    # The analysed window: from the poke to the end, or to the cut, or to the first non-finite sample.
    finite = np.isfinite(alpha)
    last = t.size if finite.all() else int(np.argmin(finite))
    fallen = np.flatnonzero(np.abs(np.where(finite, alpha, 0.0)) >= FALLEN_ANGLE)
    if fallen.size:  # the response ends where the pendulum starts its fall (read what came before)
        first = int(np.searchsorted(t, poke_start))
        start = _fall_start(alpha, int(fallen[0]), q)
        # A fall that was already under way at the poke leaves no response to read.
        last = min(last, start if _fall_run_start(alpha, int(fallen[0])) > first else first)
    window = (t >= poke_start) & (np.arange(t.size) < last)
    if cut is not None:
        window &= t <= cut
    idx = np.flatnonzero(window)
    bounded = bool(finite.all() and np.max(np.abs(alpha)) < FALLEN_ANGLE)
    if idx.size < 3 or not math.isfinite(initial):
        metrics["stable"] = False
        return metrics
    tw, aw = t[idx], alpha[idx]

    # Final value: the mean of the analysed window's tail. It is reported once the angle is known to
    # have settled there; a run that was cut or fell must have settled before its end for it to count
    # (the old lab's PIDs settle, then the cart drifts into the track limit).
    ended_early = cut is not None or not bounded
    n_tail = max(1, int(round(TAIL_FRACTION * idx.size)))
    final = float(np.mean(aw[-n_tail:]))
    reference = final if not ended_early else initial

    amplitude = float(np.max(np.abs(aw - initial)))
    tiny = 1e-12 * max(1.0, abs(initial))
    if amplitude <= max(q, tiny):
        # No measurable response (within one encoder step): nothing oscillated, nothing to settle.
        metrics["stable"] = bool(cut is None and bounded)
        metrics["final_value_rad"] = final
        return metrics

    # Hysteresis: one encoder step, and never below 1 % of the response (numerical noise).
    h = max(q, 0.01 * amplitude)

    # First peak: the extremum of the first swing away from the initial value that reaches a tenth
    # of the response (a staircase step or a tiny wiggle before it does not count), and that turns
    # after the poke (not a jump already present at the poke's first sample).
    from_initial = _lobes(tw, aw - initial, h)
    significant = max(h, 0.1 * amplitude)
    peak = next(
        (lobe for lobe in from_initial if lobe.peak_index > 0 and abs(aw[lobe.peak_index] - initial) > significant),
        None,
    )
    peak_dev = None
    if peak is not None and peak.closed:
        peak_dev = abs(float(aw[peak.peak_index]) - initial)
        metrics["peak_time_s"] = peak.peak_time - poke_start

    # Settling: the last time the angle entered the band around the final value for good.
    settled = False
    if final is not None and peak_dev is not None:
        band = max(SETTLING_FRACTION * peak_dev, q)
        # A staircase signal is up to half a step off the true angle, and its final value (a mean)
        # lies between steps: allow that half step, or a signal resting one step off never settles.
        slack = 0.5 * q if _is_quantized(aw, q) else 0.0
        outside = np.abs(aw - final) > (band + slack) * (1 + 1e-9)
        if not outside.any():
            t_settle = tw[0]
        elif outside[-1]:
            t_settle = None
        else:
            j = int(np.flatnonzero(outside)[-1])
            t_settle = _band_entry(tw, np.abs(aw - final), band + slack, j)
        hold = TAIL_FRACTION * (tw[-1] - tw[0])
        # A record that turns NaN (a blown-up simulation) defines no final value.
        if t_settle is not None and tw[-1] - t_settle >= hold and finite.all():
            settled = True
            metrics["settling_time_s"] = max(0.0, float(t_settle) - poke_start)
            metrics["final_value_rad"] = final

    if ended_early and settled:
        reference = final  # the part before the cut defines where the angle went
    # Overshoot and frequency: the swings about the final value, from the one holding the peak on.
    if peak_dev is not None:
        about_final = _lobes(tw, aw - reference, h)
        first = _lobe_at(about_final, peak.peak_index)
        if first is not None and first.sign == peak.sign:
            k = about_final.index(first)
            following = about_final[k + 1 :]
            peak_from_ref = abs(float(aw[peak.peak_index]) - reference)
            if following and following[0].closed:
                swing = abs(float(aw[following[0].peak_index]) - reference)
                metrics["overshoot_percent"] = 100.0 * swing / peak_from_ref
            elif not following and settled:
                metrics["overshoot_percent"] = 0.0  # came back without swinging past the final value
            metrics["natural_frequency_rad_s"] = _damped_frequency(tw, aw - reference, about_final[k:], smooth=not _is_quantized(aw, q))

    # Stable: no safety cut and the swings do not grow. With stick-slip friction and quantized
    # encoders a balanced pendulum keeps a small limit cycle and never settles in the 2 % band;
    # it is still stable (the rig behaves the same way).
    not_growing = False
    if peak_dev is not None:
        n_tail = max(1, int(round(0.25 * idx.size)))
        not_growing = float(np.max(np.abs(aw[-n_tail:] - initial))) <= 2.0 * peak_dev + q
    metrics["stable"] = bool(cut is None and bounded and (settled or not_growing))
    if metrics["final_value_rad"] is None and not ended_early:
        metrics["final_value_rad"] = final

    # A sustained oscillation at the end of a run that stayed up: the friction and quantization limit
    # cycle. Its swings are the response's ending, not an overshoot of the poke's first peak.
    if not ended_early:
        cycle = _limit_cycle(tw, aw, q)
        if cycle is not None:
            metrics["limit_cycle_amplitude_rad"], metrics["limit_cycle_frequency_rad_s"] = cycle
            if peak_dev is not None and cycle[0] >= LIMIT_CYCLE_STEADINESS * peak_dev:
                metrics["overshoot_percent"] = None  # the "overshoot" would be the limit cycle itself
    return metrics


def _fall_run_start(alpha: np.ndarray, fallen: int) -> int:
    """First index of the one-way stretch of the angle that ends at ``fallen``."""
    if fallen < 2:
        return 0
    segment = alpha[: fallen + 1]
    direction = 1.0 if segment[-1] >= segment[-2] else -1.0
    steps = direction * np.diff(segment)
    back = np.flatnonzero(steps < -1e-12 * max(1.0, float(np.max(np.abs(segment)))))
    return int(back[-1]) + 1 if back.size else 0


def _fall_start(alpha: np.ndarray, fallen: int, q: float) -> int:
    """Index where the fall that ends past :data:`FALLEN_ANGLE` at ``fallen`` began.

    Walking back from ``fallen``, the fall is the last stretch over which the angle only moved
    towards it (an encoder's flat steps allowed); it began where the angle left that stretch's first
    value by more than one encoder step (at least 0.1 mrad), so a settled part before it stays in.
    """
    start = _fall_run_start(alpha, fallen)
    segment = alpha[: fallen + 1]
    direction = 1.0 if fallen < 1 or segment[-1] >= segment[-2] else -1.0
    departed = np.flatnonzero(direction * (segment[start:] - segment[start]) > max(q, 1e-4))
    return start + (int(departed[0]) if departed.size else 0)


def _limit_cycle(t: np.ndarray, alpha: np.ndarray, q: float) -> tuple[float, float] | None:
    """``(amplitude, frequency)`` of a sustained oscillation at the end of ``alpha``, else None.

    The last :data:`LIMIT_CYCLE_TAIL` of the record is split into swings about its mean (hysteresis
    of one encoder step); it is a limit cycle when it holds at least :data:`LIMIT_CYCLE_SWINGS` closed
    swings, none smaller than :data:`LIMIT_CYCLE_STEADINESS` of the largest (not decaying), with an
    amplitude (mean half peak-to-peak) of at least two encoder steps.
    """
    start = int(np.searchsorted(t, t[-1] - LIMIT_CYCLE_TAIL * (t[-1] - t[0])))
    tt, a = t[start:], alpha[start:]
    if tt.size < 8:
        return None
    dev = a - float(np.mean(a))
    spread = 0.5 * float(np.ptp(dev))
    h = max(q, 0.2 * spread, 1e-12)
    lobes = [lobe for lobe in _lobes(tt, dev, h) if lobe.closed]
    # Drop the first swing: the tail's start may cut it.
    lobes = lobes[1:]
    if len(lobes) < LIMIT_CYCLE_SWINGS:
        return None
    peaks = np.array([abs(float(dev[lobe.peak_index])) for lobe in lobes])
    if peaks.min() < LIMIT_CYCLE_STEADINESS * peaks.max():
        return None
    amplitude = float(np.mean(peaks))
    if amplitude < 2 * q or amplitude <= 0:
        return None
    frequency = _damped_frequency(tt, dev, lobes)
    return (amplitude, frequency) if frequency is not None else None


# ---------------------------------------------------------------------------------------- helpers
def _as_1d(name: str, values: Any) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise UserError(f"{name} is not a numeric array ({exc}); give a sequence of numbers") from None
    if array.ndim != 1:
        array = array.reshape(-1) if array.size in array.shape else array
    if array.ndim != 1:
        raise UserError(f"{name} has shape {array.shape}; give a 1-D array (a column of samples)")
    return array


def _is_quantized(values: np.ndarray, q: float) -> bool:
    """True when every value is a whole number of encoder steps ``q`` (an encoder's staircase)."""
    if q <= 0:
        return False
    steps = values / q
    return bool(np.all(np.abs(steps - np.round(steps)) < 1e-6))


def _initial_value(t: np.ndarray, alpha: np.ndarray, poke_start: float) -> float:
    """Median of the angle over the last 0.1 s before the poke (the first sample if none).

    ``t`` is strictly increasing (checked by :func:`compute_metrics`): the window is found by bisection,
    and the median is read off the sorted values as :func:`numpy.median` computes it (the middle value,
    or the mean of the middle two), without its overhead: a sweep measures thousands of runs.
    """
    lo, hi = np.searchsorted(t, (poke_start - 0.1, poke_start), side="left")
    values = alpha[lo:hi] if hi > lo else alpha[:1]
    values = np.sort(values[np.isfinite(values)])
    n = values.size
    if not n:
        return math.nan
    return float(values[n // 2]) if n % 2 else float((values[n // 2 - 1] + values[n // 2]) / 2)


#: The cart speed change compares mean speeds over windows this long (s): the last one before the
#: end (or the cut), and the one before the poke. A mean over a window is the cart's net movement
#: divided by the window, so stick-slip's jerks and the speed's quantization noise average out.
SPEED_WINDOW = 1.0
#: The window before the poke (the pendulum balanced at rest; a shorter one if the run starts later).
SPEED_WINDOW_BEFORE = 0.5


def _speed_change(t: np.ndarray, xdot: np.ndarray, poke_start: float, cut: float | None = None) -> float | None:
    """Mean cart speed over the last :data:`SPEED_WINDOW` s (up to the cut) minus its mean over the
    :data:`SPEED_WINDOW_BEFORE` s before the poke (m/s)."""
    if xdot.size != t.size:
        raise UserError(f"xdot has {xdot.size} samples but t has {t.size}; give both at the same times")
    finite = np.isfinite(xdot)
    end = t[finite][-1] if finite.any() else t[-1]
    if cut is not None:
        end = min(end, cut)
    end = max(end, poke_start)

    def mean(lo: float, hi: float) -> float:
        # The samples with lo <= t <= hi (t is strictly increasing), the finite ones.
        a, b = np.searchsorted(t, lo, side="left"), np.searchsorted(t, hi, side="right")
        keep = finite[a:b]
        tt, v = t[a:b][keep], xdot[a:b][keep]
        if tt.size >= 2:
            return float(np.sum(0.5 * (v[1:] + v[:-1]) * np.diff(tt)) / (tt[-1] - tt[0]))  # trapezoid mean
        return float(v[0]) if v.size else math.nan

    before = mean(poke_start - SPEED_WINDOW_BEFORE, poke_start - 1e-12) if t[0] < poke_start else math.nan
    if not math.isfinite(before):
        before = float(xdot[0]) if finite[0] else math.nan
    after = mean(max(poke_start, end - SPEED_WINDOW), end)
    if not (math.isfinite(before) and math.isfinite(after)):
        return None
    return after - before


def _lobes(t: np.ndarray, dev: np.ndarray, h: float) -> list[_Lobe]:
    """Split ``dev`` into swings beyond ``±h`` (hysteresis: a swing ends when the other side is reached)."""
    side = np.where(dev > h, 1, np.where(dev < -h, -1, 0))
    marks = np.flatnonzero(side != 0)
    if marks.size == 0:
        return []
    # Each change of side among the marked samples starts a new lobe; a lobe's extent runs until the
    # next lobe begins (or the end of the record). All lobes are read at once (a long limit cycle has
    # hundreds), each on its side of the reference: its samples times its sign.
    changes = np.flatnonzero(np.diff(side[marks]) != 0) + 1
    firsts = marks[np.concatenate(([0], changes))]
    last_marked = marks[np.concatenate((changes, [marks.size])) - 1]
    stops = np.append(marks[changes], dev.size)
    signs = side[firsts]
    lengths = stops - firsts
    oriented = dev[firsts[0] :] * np.repeat(signs, lengths)
    tops = np.maximum.reduceat(oriented, firsts - firsts[0])
    # The extremum's plateau (a quantized peak is flat): its first and last sample.
    on_top = np.flatnonzero(oriented >= np.repeat(tops - 1e-12 * np.maximum(1.0, np.abs(tops)), lengths)) + firsts[0]
    i0 = on_top[np.searchsorted(on_top, firsts)]
    i1 = on_top[np.searchsorted(on_top, stops) - 1]
    peak_times = 0.5 * (t[i0] + t[i1])
    flipped = -dev  # the deviation as seen from a lobe below the reference
    lobes = []
    for sign, first, last, i, j, peak_time in zip(signs.tolist(), firsts.tolist(), last_marked.tolist(), i0.tolist(), i1.tolist(), peak_times.tolist()):
        if i == j and 0 < i < dev.size - 1:  # a sharp (unquantized) peak
            peak_time = _parabolic_peak(t, dev if sign > 0 else flipped, i)
        lobes.append(_Lobe(sign, first, last, i, peak_time, True))
    # Closed: the signal left the top by more than the hysteresis before the lobe's end (every lobe
    # but the last ends where the next one begins).
    after = oriented[i1[-1] - firsts[0] :]
    if not (after.size and tops[-1] - after.min() > h):
        lobes[-1] = lobes[-1]._replace(closed=False)
    return lobes


def _lobe_at(lobes: list[_Lobe], index: int) -> _Lobe | None:
    """The lobe whose extent (its first sample up to the next lobe's first sample) holds ``index``."""
    for lobe, following in zip(lobes, lobes[1:] + [None]):
        if lobe.start <= index and (following is None or index < following.start):
            return lobe
    return None


def _parabolic_peak(t: np.ndarray, y: np.ndarray, i: int) -> float:
    """Vertex time of the parabola through three samples around a sharp (unquantized) maximum."""
    t0, t1, t2 = t[i - 1], t[i], t[i + 1]
    y0, y1, y2 = y[i - 1], y[i], y[i + 1]
    denom = (t0 - t1) * (t0 - t2) * (t1 - t2)
    a = (t2 * (y1 - y0) + t1 * (y0 - y2) + t0 * (y2 - y1)) / denom
    b = (t2**2 * (y0 - y1) + t1**2 * (y2 - y0) + t0**2 * (y1 - y2)) / denom
    if a >= 0:
        return float(t1)
    vertex = -b / (2 * a)
    return float(vertex) if t0 <= vertex <= t2 else float(t1)


def _band_entry(t: np.ndarray, dist: np.ndarray, band: float, j: int) -> float:
    """Time the distance ``dist`` fell below ``band`` between samples ``j`` (outside) and ``j+1``."""
    d0, d1 = dist[j], dist[j + 1]
    if d0 == d1:
        return float(t[j + 1])
    frac = min(1.0, max(0.0, (d0 - band) / (d0 - d1)))
    return float(t[j] + frac * (t[j + 1] - t[j]))


def _crossing(t: np.ndarray, dev: np.ndarray, left: _Lobe, right: _Lobe) -> float:
    """Time ``dev`` crosses zero going from lobe ``left`` to lobe ``right``."""
    seg = slice(left.peak_index, right.start + 1)
    y = left.sign * dev[seg]
    ts = t[seg]
    # First sample at or past zero after the left lobe's peak.
    k = int(np.flatnonzero(y <= 0)[0])
    if y[k] < 0:
        return float(ts[k - 1] + (ts[k] - ts[k - 1]) * y[k - 1] / (y[k - 1] - y[k]))
    # The signal rests exactly on the reference for a while: take the middle of that stretch.
    k_end = k + int(np.argmax(y[k:] < 0))
    return float(0.5 * (ts[k] + ts[k_end]))


def _damped_frequency(t: np.ndarray, dev: np.ndarray, lobes: list[_Lobe], smooth: bool = False) -> float | None:
    """Damped frequency from the spacing of the swings' extremes (smooth signals), else the crossings.

    The extremes of a damped oscillation ``exp(-s t) sin(w t + phi)`` about a constant are exactly
    ``pi / w`` apart, and unlike the crossings of the final value they hardly move when the level the
    angle swings about drifts (a PID's integrator, a cart that drifts into its track limit). For a
    ``smooth`` signal with at least three closed swings the extremes' times are fitted by a straight
    line. A staircase (an encoder's reading) has flat extremes whose middles are biased on small
    swings: there, and with fewer swings, the crossings are used.
    """
    closed = [lobe for lobe in lobes if lobe.closed]
    if smooth and len(closed) >= 3 and len(closed) == len(lobes[: len(closed)]):
        peaks = np.array([lobe.peak_time for lobe in closed])
        k = np.arange(peaks.size)
        half_period = float(np.polyfit(k, peaks, 1)[0])
        if half_period > 0:
            return math.pi / half_period
    crossings = np.array([_crossing(t, dev, a, b) for a, b in zip(lobes, lobes[1:])])
    n = crossings.size
    if n >= 3:
        k = np.arange(n)
        design = np.column_stack((np.ones(n), k, (-1.0) ** k))
        half_period = float(np.linalg.lstsq(design, crossings, rcond=None)[0][1])
    elif n == 2:
        half_period = float(crossings[1] - crossings[0])
    elif n == 1 and lobes[1].closed:
        half_period = lobes[1].peak_time - lobes[0].peak_time
    else:
        return None
    return math.pi / half_period if half_period > 0 else None
