"""The fit's last stage and its check: the logs replayed under the true stick-slip law.

:func:`pendulab.calibration.fit.fit_parameters` first solves a smoothed problem (multiple shooting);
the smoothing that makes it solvable also biases it. Here the answer is polished on what the fit is
finally judged by, a replay of every log through the plant with the law's switches as they are
(:mod:`pendulab.calibration._replay`):

* **anchors** (:class:`Anchors`): the replay restarts wherever the log says what the state is: late
  in each rest of the cart (position and speed from a line through the positions there: a stuck cart
  still creeps in the lab's law); for an upright pendulum, which is open-loop unstable, also every
  :data:`UNSTABLE_WINDOW` seconds from the fit's state estimate;
* **polish** (:func:`polish`): scans of the thresholds, then a pattern search on the replay's
  position (and angle) errors, each step trying all its moves in one batched replay;
* **uncertainty** (:func:`part_spread`, :func:`profile_width`): the logs are cut into parts at
  restarts, the polish is repeated on each part from the answer, and the spread of the parts' answers
  gives the standard uncertainty (a jackknife over the parts), at least the width of the cost's
  profile around the answer. It measures what a different stretch of log would have said, which the
  residual's noise level, strongly correlated along a replay, does not.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pendulab.calibration._replay import replay
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import MAX_SUBSTEP

#: A rest: the logged position stays within this many encoder steps (or 6 noise sigmas) for REST_WINDOW.
REST_STEPS = 2.5
REST_WINDOW = 0.02
#: An upright pendulum's replay restarts from the state estimate this often (s).
UNSTABLE_WINDOW = 0.25


@dataclass
class Anchors:
    """One log prepared for replays: its data, first state and restarts.

    Attributes
    ----------
    V, t : array (n,)
        The voltage and times of the steps (the log without its last sample).
    measured : array (n, n_out)
        Logged position (and angle) after each step.
    sigma : array (n_out,)
        Measurement noise, the weights of the errors.
    x0 : array (4,)
        State at the first sample.
    restarts : dict
        ``{k: state}`` at which the replay continues from a known state.
    segments : array
        Start sample of each stretch between rests, for cutting the log into parts.
    """

    V: np.ndarray
    t: np.ndarray
    measured: np.ndarray
    sigma: np.ndarray
    x0: np.ndarray
    restarts: dict[int, np.ndarray]
    segments: np.ndarray
    denoised: bool = False  # V is the logged voltage through denoised_voltage

    @property
    def n(self) -> int:
        return len(self.V)

    def crop(self, start: int, stop: int, x0: np.ndarray | None = None) -> "Anchors":
        """Steps ``start`` to ``stop``, from ``x0`` (default: the known state there, at 0 or a restart)."""
        if x0 is None:
            x0 = self.x0 if start == 0 else self.restarts[start]
        restarts = {k - start: s for k, s in self.restarts.items() if start < k < stop}
        segments = self.segments[(self.segments >= start) & (self.segments < stop)] - start
        return Anchors(self.V[start:stop], self.t[start:stop], self.measured[start:stop], self.sigma, x0, restarts, segments, self.denoised)


def rests(x: np.ndarray, step: float, noise: float, period: float) -> list[tuple[int, int]]:
    """Rests of the cart, ``[(first, stop), ...]``: runs where the position stays put for :data:`REST_WINDOW`.

    In the lab's law a stuck cart is not quite still: friction cancels the motor's force, while
    ``Beq`` slows the speed it entered with (below ``v1``) only exponentially, over a time ``Mc/Beq``.
    """
    w = max(3, int(round(REST_WINDOW / period)))
    if len(x) <= w:
        return []
    windows = np.lib.stride_tricks.sliding_window_view(x, w)
    still = np.ptp(windows, axis=1) <= max(REST_STEPS * step, 6.0 * noise)
    edges = np.diff(np.r_[0, still.astype(np.int8), 0])
    begins, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(b), int(e) + w - 1) for b, e in zip(begins, ends)]


def anchors(log, used: int, nodes: np.ndarray, node_stride: int, sigma: np.ndarray, step: float, with_pendulum: bool) -> Anchors:
    """Restarts of one log: its rests, and for an upright pendulum the fit's state every window.

    ``nodes`` ``(ns, N+1)`` are the fit's state estimates at samples ``0, node_stride, ...``.
    """
    ns = nodes.shape[0]
    x0 = np.r_[nodes[:, 0], np.zeros(4 - ns)]
    restarts: dict[int, np.ndarray] = {}
    upright = with_pendulum and log.alpha is not None and float(np.median(np.abs(log.alpha))) < math.pi / 2
    if not with_pendulum:
        w = max(3, int(round(REST_WINDOW / log.period)))
        spans = rests(log.x[:used], step, float(sigma[0]), log.period)
        if spans and spans[0][0] == 0:
            # A log that starts at rest starts from the rest's line, not from a smoothed speed: a stuck
            # cart keeps a speed below v1 (decaying over Mc/Beq), and 1 mm/s too much is a lasting 0.1 mm.
            hi = min(spans[0][1], 3 * w)
            slope, value = np.polyfit(log.t[:hi] - log.t[0], log.x[:hi], 1)
            x0[:2] = [float(value), float(slope)]
        for first, stop in spans:
            # Late in the rest, where the creep has died down; position and speed from a line through
            # the positions around that sample (the encoder's steps average out over it).
            k = max(first, stop - w)
            if 0 < k < used - 1:
                lo, hi = max(first, k - 2 * w), min(stop, k + w)
                slope, value = np.polyfit(log.t[lo:hi] - log.t[k], log.x[lo:hi], 1)
                restarts[k] = np.array([float(value), float(slope), 0.0, 0.0])
    if upright:
        every = max(1, int(round(UNSTABLE_WINDOW / (node_stride * log.period))))
        for j in range(every, nodes.shape[1] - 1, every):
            restarts[j * node_stride] = nodes[:, j].copy()
    columns = [log.x[1:used]] + ([log.alpha[1:used]] if with_pendulum else [])
    segments = np.unique(np.r_[0, sorted(restarts)]).astype(int)
    return Anchors(
        V=log.V[: used - 1], t=log.t[: used - 1], measured=np.column_stack(columns), sigma=sigma, x0=x0,
        restarts=restarts, segments=segments,
    )


#: Logged voltage noise (V, robust estimate) above which a median-filtered voltage is also tried.
VOLTAGE_NOISE = 1e-3
#: The median filter's length (samples): it keeps steps and ramps, and takes the sample noise down about 2.3 times.
VOLTAGE_MEDIAN = 9


def voltage_noise(V: np.ndarray) -> float:
    """Robust estimate of the sample noise on a logged voltage (V): the spread of its second differences.

    Steps, ramps and slow sines have (nearly) no second difference except at a few edges, which the
    median absolute deviation ignores; white noise of ``sigma`` has second differences of ``sqrt(6) sigma``.
    """
    if len(V) < 5:
        return 0.0
    d2 = np.diff(np.asarray(V, dtype=float), 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6))


def denoised_voltage(V: np.ndarray) -> np.ndarray:
    """The logged voltage through a :data:`VOLTAGE_MEDIAN`-sample median filter (edges kept)."""
    from scipy.ndimage import median_filter

    return median_filter(np.asarray(V, dtype=float), size=VOLTAGE_MEDIAN, mode="nearest")


def denoised(a: Anchors) -> Anchors:
    """``a`` with its voltage through :func:`denoised_voltage` if it is noisy (else ``a`` itself)."""
    if a.denoised or voltage_noise(a.V) <= VOLTAGE_NOISE:
        return a
    return Anchors(denoised_voltage(a.V), a.t, a.measured, a.sigma, a.x0, a.restarts, a.segments, True)


def replay_errors(logs: list[Anchors], vectors: np.ndarray, free: tuple[str, ...], max_substep: float = MAX_SUBSTEP) -> np.ndarray:
    """Weighted replay errors, ``(m, n_errors)``, for parameter sets ``vectors`` ``(m, n_params)``."""
    rows = []
    for a in logs:
        states = replay(vectors, a.V, a.t, a.x0, a.restarts, free=free, max_substep=max_substep)
        simulated = states[:, :, [0, 2][: a.measured.shape[1]]]
        errors = (simulated - a.measured[None]) / a.sigma[None, None, :]
        rows.append(errors.reshape(errors.shape[0], -1))
    return np.concatenate(rows, axis=1)


@dataclass
class Polished:
    theta: np.ndarray
    cost: float
    start_cost: float
    iterations: int
    replays: int

    def then(self, later: "Polished", replays: int = 0) -> "Polished":
        """This search continued by ``later`` (from this one's answer), with ``replays`` more in between."""
        return Polished(later.theta, later.cost, self.start_cost, self.iterations + later.iterations, self.replays + later.replays + replays)


@dataclass(frozen=True)
class Space:
    """The fitted parameters as the search sees them: scaled values ``theta`` (value / scale).

    ``params0`` gives every parameter that is not fitted; ``lower``/``upper`` bound ``theta``;
    ``prior`` is ``(centre, weight)`` of the fit's weak prior, or None.
    """

    params0: PlantParameters
    names: tuple[str, ...]
    scales: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    prior: tuple[np.ndarray, float] | None = None

    def vectors(self, thetas: np.ndarray) -> np.ndarray:
        """Full parameter vectors ``(m, n_params)`` for scaled values ``(m, n)``."""
        all_names = PlantParameters.names()
        out = np.tile(np.asarray(self.params0.as_vector(), dtype=float), (thetas.shape[0], 1))
        out[:, [all_names.index(n) for n in self.names]] = thetas * self.scales[None, :]
        return out

    def project(self, th: np.ndarray) -> np.ndarray:
        """Within the bounds, with ``F1 <= F2`` and ``v1 <= v2`` (a crossed pair meets in the middle)."""
        th = np.clip(th, self.lower, self.upper)
        names, scales = self.names, self.scales
        value = dict(zip(names, th * scales))
        for low, high in (("F1", "F2"), ("v1", "v2")):
            if low in value and high in value and value[low] > value[high]:
                mid = 0.5 * (value[low] + value[high])
                th[names.index(low)], th[names.index(high)] = mid / scales[names.index(low)], mid / scales[names.index(high)]
        return th

    def residuals(self, logs: list[Anchors], thetas: np.ndarray, max_substep: float = MAX_SUBSTEP) -> np.ndarray:
        """Weighted replay errors and the prior's residuals, ``(m, n_residuals)``."""
        r = replay_errors(logs, self.vectors(thetas), self.names, max_substep)
        if self.prior is None:
            return r
        centre, weight = self.prior
        return np.concatenate([r, math.sqrt(weight) * (thetas - centre[None, :])], axis=1)


def polish(
    logs: list[Anchors],
    space: Space,
    theta: np.ndarray,
    max_iter: int = 12,
    first_step: float = 0.02,
    min_step: float = 1e-3,
    work: float = math.inf,
    scan: tuple[str, ...] = ("F1", "F2", "v2"),
    scan_spans: tuple[float, ...] = (2.0, 0.15, 0.015),
    scan_points: int = 15,
    scan_rounds: int = 2,
    scan_substep: float = MAX_SUBSTEP,
    pairs: tuple[tuple[str, str], ...] = (("F2", "v2"), ("F1", "F2"), ("Beq", "force_gain")),
) -> Polished:
    """A pattern search on the replay errors over the scaled parameters ``theta``.

    The replay's error is not smooth in the parameters: a breakaway that happens or not is a jump, so
    derivatives (even finite differences) mislead. The parameters ``scan`` (the thresholds whose
    jumps dominate) are first scanned one by one over ``scan_spans`` (relative, coarse then fine,
    ``scan_points`` factors each, log-spaced within ``1 + span`` either way: a factor 3 first, for a
    smoothed answer caught in a wrong basin; ``scan_rounds`` times, as they interact). Each iteration tries every
    parameter up and down by a relative ``radius``, the four diagonal moves of each of ``pairs``
    (parameters that trade off: the slip region's corner ``F2, v2``, the two forces, and ``Beq``
    against the force gain, which both set a steady speed) and the last good move, all in one batched replay, and keeps the
    best if it lowers the cost; otherwise the radius shrinks threefold, down to ``min_step``. The
    order constraints ``F1 <= F2`` and ``v1 <= v2`` and the bounds are kept by projection. It stops
    early once it has replayed ``work`` samples (parameter sets x samples), a bound that, unlike a
    clock, gives the same answer on a busy machine.
    """
    names, project = space.names, space.project
    done = {"samples": 0.0}
    n_samples = sum(a.n for a in logs)

    def residuals(thetas: np.ndarray, max_substep: float = MAX_SUBSTEP) -> np.ndarray:
        done["samples"] += thetas.shape[0] * n_samples
        return space.residuals(logs, thetas, max_substep)

    theta = project(np.asarray(theta, dtype=float).copy())
    r = residuals(theta[None])[0]
    cost = start_cost = float(r @ r)
    radius, replays, it, n = first_step, 1, 0, len(theta)
    # The thresholds first: whether a push breaks the cart away (F1) or slides it freely (F2) is a
    # jump in the replay, and a smoothed fit's threshold a few per cent off misses whole motions.
    # A scan along each (coarse, then fine around the best), one batched replay per scan, at the
    # sub-step ``scan_substep`` (each scan holds the current value, so its costs compare among
    # themselves); the answer is kept if the replay at the plant's own sub-step agrees it is better.
    # (A coarser sub-step, 0.5 ms, is three times faster and helped a sweep and ramps, but it sent a
    # log of steps into a worse basin: the plant's own is the default.)
    scanned = theta
    for name in [n_ for n_ in scan if n_ in names] * scan_rounds:
        j = names.index(name)
        for span in scan_spans:
            if done["samples"] > work:
                break
            trials = np.tile(scanned, (scan_points, 1))
            trials[:, j] = scanned[j] * np.exp(np.linspace(-math.log1p(span), math.log1p(span), scan_points))
            trials = np.array([project(th) for th in trials])
            R = residuals(trials, scan_substep)
            replays += 1
            scanned = trials[int(np.argmin(np.einsum("ij,ij->i", R, R)))]
    if scanned is not theta:
        r_scanned = residuals(scanned[None])[0]
        replays += 1
        if float(r_scanned @ r_scanned) < cost:
            theta, r, cost = scanned, r_scanned, float(r_scanned @ r_scanned)
    momentum = np.zeros(n)
    for it in range(1, max_iter + 1):
        if done["samples"] > work:
            break
        # Every parameter up and down by the radius (relative), and the last accepted move again,
        # all in one batched replay.
        size = radius * np.maximum(np.abs(theta), 1e-2)
        diagonal = []
        for a_, b_ in pairs:
            if a_ in names and b_ in names:
                i_, j_ = names.index(a_), names.index(b_)
                for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                    m_ = np.zeros(n)
                    m_[i_], m_[j_] = si * size[i_], sj * size[j_]
                    diagonal.append(m_)
        moves = np.vstack([np.diag(size), -np.diag(size), *([np.array(diagonal)] if diagonal else []), momentum[None, :]])
        trials = np.array([project(theta + m) for m in moves])
        R = residuals(trials)
        replays += 1
        costs = np.einsum("ij,ij->i", R, R)
        best = int(np.argmin(costs))
        if costs[best] < cost * (1 - 1e-6):
            momentum = trials[best] - theta
            theta, r, cost = trials[best], R[best], float(costs[best])
        else:
            momentum = np.zeros(n)
            radius /= 3.0
            if radius < min_step:
                break
    return Polished(theta=theta, cost=cost, start_cost=start_cost, iterations=it, replays=replays)


#: Pairs whose joint effect makes narrow valleys of the replay's cost: leaving the slip region
#: happens at ``min(F2, (B + Beq) v2)`` of drive, so ``v2`` trades off against ``F2`` and ``B``, and the
#: re-sticking at ``v1`` against where the slip region ends.
VALLEY_PAIRS = (("F2", "v2"), ("v1", "v2"), ("B", "v2"))


def refine_pairs(
    logs: list[Anchors],
    space: Space,
    theta: np.ndarray,
    pairs: tuple[tuple[str, str], ...] = VALLEY_PAIRS,
    fine: float = 0.015,
    coarse: float = 0.1,
    n_fine: int = 4,
    n_coarse: int = 8,
) -> tuple[np.ndarray, float]:
    """Grids over pairs of parameters, one fine and one coarse axis, to step along narrow valleys.

    A pattern search moves each parameter (or a pair, equally) by one radius, so it stops in a valley
    that runs at a slant: along it ``v2`` may move by 6 % while ``F2`` moves by 0.4 %, and either move
    alone raises the cost twentyfold. Here each pair is gridded both ways round (``n_fine`` relative
    offsets within ``fine`` on one axis times ``n_coarse`` within ``coarse`` on the other, 32 parameter
    sets: one batched replay each); the best point is kept whenever it lowers the cost. Returns the
    new ``theta`` and its cost.
    """
    names = space.names
    r = space.residuals(logs, theta[None])[0]
    cost = float(r @ r)
    fine_steps = np.exp(np.linspace(-math.log1p(fine), math.log1p(fine), n_fine))
    coarse_steps = np.exp(np.linspace(-math.log1p(coarse), math.log1p(coarse), n_coarse))
    for a_, b_ in pairs:
        if a_ not in names or b_ not in names:
            continue
        for f_name, c_name in ((a_, b_), (b_, a_)):
            i, j = names.index(f_name), names.index(c_name)
            trials = np.tile(theta, (fine_steps.size * coarse_steps.size, 1))
            trials[:, i] *= np.repeat(fine_steps, coarse_steps.size)
            trials[:, j] *= np.tile(coarse_steps, fine_steps.size)
            trials = np.array([space.project(th) for th in trials])
            R = space.residuals(logs, trials)
            costs = np.einsum("ij,ij->i", R, R)
            k = int(np.argmin(costs))
            if costs[k] < cost:
                theta, cost = trials[k], float(costs[k])
    return theta, cost


def log_parts(logs: list[Anchors], n_parts: int) -> list[list[Anchors]]:
    """The logs cut into ``n_parts`` stretches of about equal length, each starting at a known state."""
    total = sum(a.n for a in logs)
    bounds = np.linspace(0, total, n_parts + 1)
    parts: list[list[Anchors]] = [[] for _ in range(n_parts)]
    offset = 0
    for a in logs:
        cuts = np.r_[a.segments, a.n]
        # The part of each stretch between rests, by where its middle falls; then one crop per run of stretches.
        owner = np.minimum(np.searchsorted(bounds, offset + 0.5 * (cuts[:-1] + cuts[1:]), side="right") - 1, n_parts - 1)
        start = 0
        for s in range(1, len(owner) + 1):
            if s == len(owner) or owner[s] != owner[start]:
                parts[int(owner[start])].append(a.crop(int(cuts[start]), int(cuts[s])))
                start = s
        offset += a.n
    return [p for p in parts if p]


def part_spread(
    logs: list[Anchors],
    space: Space,
    theta: np.ndarray,
    n_parts: int = 4,
    max_iter: int = 6,
    resolution: float = 3e-4,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Standard uncertainty of ``theta`` from refits on parts of the logs (None if they cannot be cut).

    Each part is polished on its own from ``theta``; with ``K`` parts, each holding ``1/K`` of the
    data, the whole logs' answer varies ``sqrt(K)`` times less than the parts' answers do. The search
    stops at steps of ``resolution`` (relative), which is also the smallest spread reported.

    Returns
    -------
    sigma, estimates
        The standard uncertainty of each scaled parameter and the parts' answers ``(K, n)``.
    """
    parts = log_parts(logs, n_parts)
    if len(parts) < 2:
        return None
    estimates = np.array([
        polish(part, space, theta, max_iter=max_iter, first_step=0.01, min_step=resolution, scan=()).theta
        for part in parts
    ])
    spread = np.std(estimates, axis=0, ddof=1) / math.sqrt(len(parts))
    return np.maximum(spread, resolution * np.abs(theta)), estimates


#: Relative offsets of the profile scan around the answer (each side).
PROFILE_OFFSETS = (0.001, 0.003, 0.01, 0.03, 0.1)


def profile_width(logs: list[Anchors], space: Space, theta: np.ndarray) -> np.ndarray:
    """How far each parameter can move, the others kept, before the replay gets worse (scaled units).

    (The prior is left out: it is negligible against the logs.)

    A threshold the logs never cross (no push between two breakaway forces, say) leaves the cost flat
    over a range; refits of parts then agree and their spread says nothing. Here each parameter is
    moved by :data:`PROFILE_OFFSETS` both ways in one batched replay, and the half-width is the largest
    offset at which the cost stays within ``cost / segments`` of the answer's (the cost of one of the
    roughly independent stretches between restarts).
    """
    n = len(theta)
    offsets = np.array([s * o for o in PROFILE_OFFSETS for s in (-1.0, 1.0)])
    trials = [theta.copy()]
    for j in range(n):
        for o in offsets:
            th = theta.copy()
            th[j] = theta[j] * (1.0 + o) if abs(theta[j]) > 1e-12 else o
            trials.append(np.clip(th, space.lower, space.upper))
    R = replay_errors(logs, space.vectors(np.array(trials)), space.names)
    costs = np.einsum("ij,ij->i", R, R)
    segments = sum(len(a.segments) for a in logs)
    limit = costs[0] * (1.0 + 1.0 / max(segments, 1))
    widths = np.zeros(n)
    for j in range(n):
        c = costs[1 + j * len(offsets) : 1 + (j + 1) * len(offsets)]
        inside = np.abs(offsets[c <= limit])
        widths[j] = (inside.max() if inside.size else 0.0) * abs(theta[j])
    return widths


def linearized_sigma(logs: list[Anchors], space: Space, theta: np.ndarray, step: float = 3e-3) -> np.ndarray:
    """Standard uncertainty of ``theta`` from the replay's linearization, with correlated errors.

    ``sqrt(diag((J^T J)^-1)) * s * sqrt(k)``: ``J`` is the replay errors' Jacobian by central
    differences (relative ``step``, one batched replay), ``s`` the RMS error at ``theta`` and ``k``
    the errors' correlation length in samples (a replay's errors come in runs, not independently).
    The inverse keeps the correlations between parameters that a refit of parts, started from the
    answer, misses: ``Beq`` and the force gain off together by a per cent leave the steady speeds
    unchanged.
    """
    n = len(theta)
    size = step * np.maximum(np.abs(theta), 1e-2)
    trials = np.vstack([theta, theta + np.diag(size), theta - np.diag(size)])
    R = np.nan_to_num(replay_errors(logs, space.vectors(trials), space.names), nan=0.0)
    r0 = R[0]
    J = ((R[1 : n + 1] - R[n + 1 :]) / (2 * size[:, None])).T
    s2 = float(np.mean(r0**2))
    # Correlation length: 1 + 2 * the sum of the autocorrelation up to its first zero (per log, sample-weighted).
    lengths, weights = [], []
    offset = 0
    for a in logs:
        e = r0[offset : offset + a.measured.size]
        offset += a.measured.size
        e = e - e.mean()
        if e.size < 4 or not np.any(e):
            continue
        spectrum = np.fft.rfft(e, 2 * e.size)
        acf = np.fft.irfft(spectrum * np.conj(spectrum))[: e.size]
        acf = acf / acf[0]
        stop = int(np.argmax(acf <= 0)) if np.any(acf <= 0) else e.size
        lengths.append(1.0 + 2.0 * float(np.sum(acf[1:stop])))
        weights.append(e.size)
    k = float(np.average(lengths, weights=weights)) if lengths else 1.0
    try:
        covariance = np.linalg.pinv(J.T @ J) * s2 * max(k, 1.0)
    except np.linalg.LinAlgError:
        return np.full(n, np.inf)
    return np.sqrt(np.clip(np.diag(covariance), 0.0, None))
