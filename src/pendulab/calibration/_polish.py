"""The fit's last stage and its check: the logs replayed under the true stick-slip law.

:func:`pendulab.calibration.fit.fit_parameters` first searches an observer of the replay (:mod:`pendulab.calibration._observer`), whose corrections
blur what a threshold a per cent off does. Here the answer is polished on what the fit is finally judged by, a replay of every log through the plant
with the law's switches as they are (:mod:`pendulab.calibration._replay`), restarted where the log gives the state (:class:`Anchors`): :func:`polish`,
and beside it :func:`scan_directions`, :func:`valley`, :func:`walk` and :func:`evolve`; :func:`profile` says what the logs determine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from pendulab import exact
from pendulab.calibration._replay import replay
from pendulab.model.parameters import PlantParameters

#: A rest: the logged position stays within this many encoder steps (or 6 noise sigmas) for REST_WINDOW.
REST_STEPS = 2.5
REST_WINDOW = 0.02
#: ... and for at least this many samples: at 100 Hz, 3 samples (30 ms) still held a cart breaking away at 38 mm/s.
REST_SAMPLES = 4
#: A rest shorter than this (s) restarts the replay's position only, its speed carried on: mostly a cart creeping near v1, whose speed the encoder's
#: steps hide (the unseen rig's slow ramps: 0.64 mm/s RMS off; the true values replayed at 0.92 steps, Beq +10 % at 0.66; carried on, 0.62 and 0.97).
RESTART_REST = 0.1
#: An upright pendulum's replay restarts from the state estimate this often (s).
UNSTABLE_WINDOW = 0.25


@dataclass
class Anchors:
    """One log prepared for replays: its data, first state and restarts (the arguments of :func:`replay`)."""

    V: np.ndarray  # (n,) the steps' voltage and times (the log without its last sample)
    t: np.ndarray
    measured: np.ndarray  # (n, n_out) logged position (and angle) after each step
    sigma: np.ndarray  # (n_out,) measurement noise, the weights of the errors
    x0: np.ndarray  # (4,) state at the first sample
    restarts: dict[int, np.ndarray]  # {k: state}: the replay continues from a known state
    segments: np.ndarray  # start sample of each stretch between rests, for cutting the log into parts
    denoised: bool = False  # V is the logged voltage through denoised_voltage

    @property
    def n(self) -> int:
        return len(self.V)

    def crop(self, start: int, stop: int, x0: np.ndarray | None = None) -> "Anchors":
        """Steps ``start`` to ``stop``, from ``x0`` (default: the first state; give it where ``start > 0``)."""
        x0 = self.x0 if x0 is None else x0
        restarts = {k - start: s for k, s in self.restarts.items() if start < k < stop}
        segments = self.segments[(self.segments >= start) & (self.segments < stop)] - start
        return Anchors(self.V[start:stop], self.t[start:stop], self.measured[start:stop], self.sigma, x0, restarts, segments, self.denoised)

    def at_rest(self) -> "Anchors":
        """These anchors with the cart at rest at the first sample (its speed 0; the smoothed speed there may be the smoothing's edge)."""
        return replace(self, x0=np.r_[self.x0[0], 0.0, self.x0[2:]])

    def first_stretch(self) -> "Anchors":
        """The steps up to the first restart (all of them if there is none)."""
        return self.crop(0, int(self.segments[1]) if self.segments.size > 1 else self.n)


def rest_samples(period: float) -> int:
    """The samples a rest lasts at least (:data:`REST_WINDOW`, :data:`REST_SAMPLES`)."""
    return max(REST_SAMPLES, int(round(REST_WINDOW / period)))


def rests(x: np.ndarray, step: float, noise: float, period: float) -> list[tuple[int, int]]:
    """Rests of the cart, ``[(first, stop), ...]``: runs where the position stays put for :data:`REST_WINDOW`.

    In the lab's law a stuck cart creeps: friction cancels the motor's force, while ``Beq`` slows its speed (below ``v1``) only over ``Mc/Beq``.
    """
    w = rest_samples(period)
    if len(x) <= w:
        return []
    still = np.ptp(np.lib.stride_tricks.sliding_window_view(x, w), axis=1) <= max(REST_STEPS * step, 6.0 * noise)
    edges = np.diff(np.r_[0, still.astype(np.int8), 0])
    return [(int(b), int(e) + w - 1) for b, e in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]  # begins, ends


def restart_samples(spans: list[tuple[int, int]], period: float) -> list[tuple[int, bool]]:
    """``(k, long)`` per rest ``(first, stop)`` of :func:`rests`: a replay restarts at sample ``k``, late in the rest (the creep has died down),
    with the logged speed if the rest is ``long`` (:data:`RESTART_REST`), else its own."""
    w = rest_samples(period)
    return [(max(first, stop - w), (stop - first) * period >= RESTART_REST) for first, stop in spans]


def _line(t: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """``(value at t = 0, slope)`` of the least-squares line through ``(t, x)`` by :func:`exact.lstsq` (``numpy.polyfit``'s bits vary by CPU)."""
    slope, value = exact.lstsq(np.column_stack([t, np.ones_like(t)]), x)
    return float(value), float(slope)


def anchors(log, used: int, nodes: np.ndarray, node_stride: int, sigma: np.ndarray, step: float, with_pendulum: bool) -> Anchors:
    """Restarts of one log: its rests, and for an upright pendulum the fit's state every window.

    ``nodes`` ``(ns, N+1)`` are the fit's state estimates at samples ``0, node_stride, ...``.
    """
    x0 = np.r_[nodes[:, 0], np.zeros(4 - nodes.shape[0])]
    restarts: dict[int, np.ndarray] = {}
    if not with_pendulum:
        w = rest_samples(log.period)
        spans = rests(log.x[:used], step, float(sigma[0]), log.period)
        if spans and spans[0][0] == 0:
            # Starting at rest: from the rest's line, not a smoothed speed (a stuck cart creeps below v1; 1 mm/s too much is a lasting 0.1 mm).
            hi = min(spans[0][1], 3 * w)
            x0[:2] = _line(log.t[:hi] - log.t[0], log.x[:hi])
        for (first, stop), (k, long) in zip(spans, restart_samples(spans, log.period)):
            if 0 < k < used - 1:  # position and speed from a line through the positions around k (encoder steps average out)
                lo, hi = max(first, k - 2 * w), min(stop, k + w)
                value, slope = _line(log.t[lo:hi] - log.t[k], log.x[lo:hi])
                restarts[k] = np.array([value, slope if long else math.nan, 0.0, 0.0])
    if with_pendulum and float(np.median(np.abs(log.alpha))) < math.pi / 2:  # upright
        every = max(1, int(round(UNSTABLE_WINDOW / (node_stride * log.period))))
        restarts.update({j * node_stride: nodes[:, j].copy() for j in range(every, nodes.shape[1] - 1, every)})
    columns = [log.x[1:used]] + ([log.alpha[1:used]] if with_pendulum else [])
    return Anchors(V=log.V[: used - 1], t=log.t[: used - 1], measured=np.column_stack(columns), sigma=sigma, x0=x0, restarts=restarts,
                   segments=np.unique(np.r_[0, sorted(restarts)]).astype(int))


#: Finite-difference steps of a restart's state (x m, xdot m/s, alpha rad, alphadot rad/s) in :func:`settled`.
RESTART_STEPS = np.array([1e-5, 1e-4, 1e-4, 1e-3])


def settled(a: Anchors, vector: np.ndarray, free: tuple[str, ...] | None, iterations: int = 4) -> Anchors:
    """``a`` with its first state and each restart's chosen to replay its own stretch best at the parameters ``vector``.

    An observer's state estimate is causal: its speeds lag, and an upright pendulum's unstable replay grows what they miss (the unseen rig's closed
    loop: 1.4 encoder steps). Gauss-Newton on each stretch's weighted errors by central differences; a stretch keeps only steps that lower its cost.
    """
    starts = np.array([0, *sorted(a.restarts)], dtype=int)
    bounds = np.r_[starts, a.n]

    def from_states(S: np.ndarray) -> Anchors:
        return replace(a, x0=S[0].copy(), restarts={int(k): s.copy() for k, s in zip(starts[1:], S[1:])})

    def errors(S: np.ndarray) -> np.ndarray:
        return np.nan_to_num(replay_errors([from_states(S)], vector[None], free)[0].reshape(a.n, -1), nan=1e6)

    def stretch_costs(E: np.ndarray) -> np.ndarray:
        return np.add.reduceat(np.einsum("ij,ij->i", E, E), starts)

    states = np.array([a.x0, *(a.restarts[int(k)] for k in starts[1:])], dtype=float)
    E = errors(states)
    cost = stretch_costs(E)
    for _ in range(iterations):
        J = []
        for d, h in enumerate(RESTART_STEPS):
            up, down = states.copy(), states.copy()
            up[:, d] += h
            down[:, d] -= h
            J.append((errors(up) - errors(down)) / (2 * h))
        J = np.stack(J, axis=-1)  # (n, n_out, 4)
        trial = states.copy()
        for w, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
            Jw, ew = J[lo:hi].reshape(-1, 4), E[lo:hi].ravel()
            A, g = np.einsum("ki,kj->ij", Jw, Jw), np.einsum("ki,k->i", Jw, ew)  # einsum: the same sums on any machine
            trial[w] -= exact.solve(A + 1e-9 * np.trace(A) * np.eye(4) + 1e-30 * np.eye(4), g)
        E_trial = errors(trial)
        cost_trial = stretch_costs(E_trial)
        better = cost_trial < cost
        if not np.any(better):
            break
        for w in np.flatnonzero(better):
            states[w], E[bounds[w] : bounds[w + 1]] = trial[w], E_trial[bounds[w] : bounds[w + 1]]
        cost = np.where(better, cost_trial, cost)
    return from_states(states)


#: Logged voltage noise (V, robust estimate) above which the denoised voltage is also tried.
VOLTAGE_NOISE = 1e-3


def voltage_noise(V: np.ndarray) -> float:
    """Robust estimate of the sample noise on a logged voltage (V): the spread of its second differences.

    Steps, ramps and slow sines have (nearly) no second differences but at a few edges, which the MAD ignores; white noise's are ``sqrt(6) sigma``.
    """
    if len(V) < 5:
        return 0.0
    d2 = np.diff(np.asarray(V, dtype=float), 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6))


#: Jumps larger than this many noise sigmas split the voltage before trend filtering (they are steps).
JUMP_SIGMAS = 5.0
#: L1 trend filter's weight, in noise sigmas.
TREND_WEIGHT = 100.0


def trend_filter(y: np.ndarray, weight: float, tol: float = 1e-4, max_iter: int = 60) -> np.ndarray:
    """L1 trend filtering: ``argmin 1/2 |y - x|^2 + weight |D2 x|_1`` (a piecewise-linear estimate).

    Primal-dual interior point on the dual, a box-constrained QP (Kim, Koh, Boyd, Gorinevsky, SIAM Review 51, 2009): a pentadiagonal solve per step.

    Examples
    --------
    >>> ramp = np.r_[np.zeros(50), np.linspace(0, 1, 100), np.ones(50)]
    >>> noisy = ramp + np.random.default_rng(0).normal(0, 0.01, ramp.size)
    >>> bool(np.sqrt(np.mean((trend_filter(noisy, 0.3) - ramp) ** 2)) < 0.004)  # the noise: 0.0096
    True
    """
    from scipy.linalg import solveh_banded

    y = np.asarray(y, dtype=float)
    n, lam = len(y), float(weight)
    if n < 5:
        return y.copy()
    m = n - 2

    def D(x: np.ndarray) -> np.ndarray:
        return x[:-2] - 2 * x[1:-1] + x[2:]

    def DT(z: np.ndarray) -> np.ndarray:
        return np.r_[z, 0.0, 0.0] - 2 * np.r_[0.0, z, 0.0] + np.r_[0.0, 0.0, z]

    def banded(diagonal: np.ndarray | float) -> np.ndarray:  # D D^T + diag, upper banded form
        ab = np.zeros((3, m))
        ab[2], ab[1, 1:], ab[0, 2:] = 6.0 + diagonal, -4.0, 1.0
        return ab

    def dot(a: np.ndarray, b: np.ndarray) -> float:  # not BLAS: its threads spin on a busy machine
        return float(np.sum(a * b))

    Dy = D(y)
    z, mu1, mu2 = np.zeros(m), np.ones(m), np.ones(m)
    t, step, dual = 1e-10, math.inf, 0.0
    for _ in range(max_iter):
        f1, f2 = z - lam, -z - lam
        DTz = DT(z)
        DDTz = D(DTz)
        w = Dy - (mu1 - mu2)
        primal = min(0.5 * dot(w, solveh_banded(banded(0.0), w)) + lam * np.sum(mu1 + mu2), 0.5 * dot(DTz, DTz) + lam * np.sum(np.abs(Dy - DDTz)))
        dual = max(-0.5 * dot(DTz, DTz) + dot(Dy, z), dual)
        gap = primal - dual
        if gap <= tol * max(1.0, abs(dual)):
            break
        if step >= 0.2:
            t = max(4.0 * m / gap, 1.2 * t)
        dz = solveh_banded(banded(-(mu1 / f1 + mu2 / f2)), -DDTz + Dy + (1 / t) / f1 - (1 / t) / f2)
        dmu1 = -(mu1 + ((1 / t) + dz * mu1) / f1)
        dmu2 = -(mu2 + ((1 / t) - dz * mu2) / f2)
        residual = math.sqrt(dot(DDTz - w, DDTz - w) + dot(mu1 * f1 + 1 / t, mu1 * f1 + 1 / t) + dot(mu2 * f2 + 1 / t, mu2 * f2 + 1 / t))
        step = 1.0
        for mu, dmu in ((mu1, dmu1), (mu2, dmu2)):
            if np.any(dmu < 0):
                step = min(step, 0.99 * float(np.min(-mu[dmu < 0] / dmu[dmu < 0])))
        for _ in range(40):  # backtracking: stay strictly feasible and lower the residual
            nz, nmu1, nmu2 = z + step * dz, mu1 + step * dmu1, mu2 + step * dmu2
            nf1, nf2 = nz - lam, -nz - lam
            if max(nf1.max(), nf2.max()) < 0:
                r_new = D(DT(nz)) - Dy + nmu1 - nmu2
                new = math.sqrt(dot(r_new, r_new) + dot(nmu1 * nf1 + 1 / t, nmu1 * nf1 + 1 / t) + dot(nmu2 * nf2 + 1 / t, nmu2 * nf2 + 1 / t))
                if new <= (1 - 0.01 * step) * residual:
                    break
            step *= 0.5
        z, mu1, mu2 = nz, nmu1, nmu2
    return y - DT(z)


#: The denoised voltage is rounded to this many decimals (V): its banded solves (LAPACK) differ in their last bits between CPUs.
DENOISED_DECIMALS = 7


def denoised_voltage(V: np.ndarray) -> np.ndarray:
    """The applied voltage estimated from a noisy logged one, keeping its steps and its ramps.

    The voltage is split at jumps of more than :data:`JUMP_SIGMAS` noise sigmas (steps), and each piece goes through :func:`trend_filter` (piecewise
    linear: ramps, holds and their corners stay). A 9-sample median would keep steps but round a slow ramp into a staircase of the noise's size.
    """
    V = np.asarray(V, dtype=float)
    sigma = voltage_noise(V)
    if sigma <= 0:
        return V.copy()
    cuts = np.r_[0, np.flatnonzero(np.abs(np.diff(V)) > JUMP_SIGMAS * math.sqrt(2) * sigma) + 1, len(V)]
    out = V.copy()
    for a, b in zip(cuts[:-1], cuts[1:]):
        out[a:b] = trend_filter(V[a:b], TREND_WEIGHT * sigma) if b - a >= 5 else np.median(V[a:b])
    return np.round(out, DENOISED_DECIMALS)


def denoised(a: Anchors) -> Anchors:
    """``a`` with its voltage through :func:`denoised_voltage` if it is noisy (else ``a`` itself)."""
    return a if a.denoised or voltage_noise(a.V) <= VOLTAGE_NOISE else replace(a, V=denoised_voltage(a.V), denoised=True)


def replay_errors(logs: list[Anchors], vectors: np.ndarray, free: tuple[str, ...] | None) -> np.ndarray:
    """Weighted replay errors, ``(m, n_errors)``, for parameter sets ``vectors`` ``(m, n_params)``."""
    rows = []
    for a in logs:
        simulated = replay(vectors, a.V, a.t, a.x0, a.restarts, free=free)[:, :, [0, 2][: a.measured.shape[1]]]
        rows.append(((simulated - a.measured[None]) / a.sigma[None, None, :]).reshape(len(vectors), -1))
    return np.concatenate(rows, axis=1)


@dataclass
class Polished:
    """A search's answer: scaled values, cost (sum of squared weighted errors) and the start's, iterations, batched replays (or observer runs)."""

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

    ``params0`` gives every parameter not fitted; ``lower``/``upper`` bound ``theta``; ``prior`` is ``(centre, weight)`` of the weak prior, or None.
    ``inputs`` are the compiled replay's parameter inputs (default ``names``): a parameter :meth:`holding` holds stays one, its value in every set,
    not a constant compiled in (each held value compiled its own replay, 3 s of gcc each: a third of the fit tests' compiles).
    """

    params0: PlantParameters
    names: tuple[str, ...]
    scales: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    prior: tuple[np.ndarray, float] | None = None
    inputs: tuple[str, ...] = ()
    _memo: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "inputs", self.inputs or self.names)  # frozen

    def memo(self, logs: list[Anchors]) -> dict[bytes, float]:
        """The costs replayed so far on ``logs`` by their sets' bytes (the logs kept with them: their ids stay theirs)."""
        return self._memo.setdefault(tuple(map(id, logs)), (logs, {}))[1]

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

    def holding(self, name: str, value: float) -> "Space":
        """This space with ``name`` held at the scaled ``value`` (not searched)."""
        j = self.names.index(name)
        keep = [i for i in range(len(self.names)) if i != j]
        return Space(self.params0.with_values(**{name: float(value * self.scales[j])}), tuple(self.names[i] for i in keep), self.scales[keep],
                     self.lower[keep], self.upper[keep], None if self.prior is None else (self.prior[0][keep], self.prior[1]), self.inputs)

    def with_prior(self, r: np.ndarray, thetas: np.ndarray) -> np.ndarray:
        """Errors ``r`` ``(m, n_errors)`` of ``thetas`` ``(m, n)`` and the prior's residuals beside them."""
        if self.prior is None:
            return r
        centre, weight = self.prior
        return np.concatenate([r, math.sqrt(weight) * (thetas - centre[None, :])], axis=1)


def costs(logs: list[Anchors], space: Space, thetas: np.ndarray) -> np.ndarray:
    """The replay cost (sum of squared weighted errors) of each of ``thetas`` ``(m, n)``; a failed replay costs 1e6 per error.

    A set already replayed on ``logs`` is not replayed again (:meth:`Space.memo`): a scan's second round where nothing moved, a valley's own point.
    Its cost is the same bits: each set is one lane of the replay, whatever its batch.
    """
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    memo, keys = space.memo(logs), [row.tobytes() for row in thetas]
    new = list(dict.fromkeys(k for k in keys if k not in memo))
    if new:
        X = np.array([np.frombuffer(k) for k in new])
        R = space.with_prior(np.nan_to_num(replay_errors(logs, space.vectors(X), space.inputs), nan=1e6), X)
        memo.update(zip(new, np.einsum("ij,ij->i", R, R)))
    return np.array([memo[k] for k in keys])


#: The common scale's members: together they change only the inertia's share of the motion (quasi-static ``gain V = (B + Beq) v + F`` is blind to it).
SCALED = ("F1", "F2", "B", "Beq", "force_gain")


def moved(space: Space, theta: np.ndarray, direction: str, x: float) -> np.ndarray:
    """``theta`` moved ``x`` along ``direction``: a name (log), ``"scale"`` (:data:`SCALED` by ``exp(x)``) or ``"split"`` (``B``'s logit share)."""
    names = space.names
    v = theta * space.scales
    if direction == "scale":
        v[[j for j, n in enumerate(names) if n in SCALED]] *= math.exp(x)
    elif direction == "split":
        i, j = names.index("B"), names.index("Beq")
        total = v[i] + v[j]
        share = min(max(v[i] / max(total, 1e-300), 1e-6), 1 - 1e-6)
        share = 1.0 / (1.0 + math.exp(-(math.log(share / (1 - share)) + x)))
        v[i], v[j] = share * total, (1 - share) * total
    else:
        v[names.index(direction)] *= math.exp(x)
    return space.project(v / space.scales)


def directions_of(names: tuple[str, ...]) -> tuple[str, ...]:
    """The scan directions for the fitted ``names``: the common scale, the drag split, then each name."""
    out = []
    if "force_gain" in names and any(n in SCALED for n in names if n != "force_gain"):
        out.append("scale")
    if "B" in names and "Beq" in names:
        out.append("split")
    return (*out, *names)


#: The slip region's end speeds (m/s) the drag split is scanned with (:func:`scan_directions`), each with ``F2`` as it is and raised to
#: at least twice ``F1`` (:func:`slip_region`). The unseen rig's triangle wave (10 mV), stopped at 4.5 steps with ``B`` folded into ``Beq``
#: and ``F2 = F1``, leaves the slip region at ``F2`` right after each breakaway, so ``B`` never acts: with ``F2`` out of the way, 0.98 steps.
SLIP_SPEEDS = (0.01, 0.03, 0.06, 0.12)
SLIP_F2_FACTORS = (None, 2.0)


def slip_region(space: Space, theta: np.ndarray, v2: float, f2_factor: float | None) -> np.ndarray:
    """``theta`` with the slip region reaching ``v2`` (m/s) and, with ``f2_factor``, ``F2`` at least that many times ``F1``."""
    names, th = space.names, np.array(theta, dtype=float)
    th[names.index("v2")] = v2 / space.scales[names.index("v2")]
    if f2_factor is not None and "F1" in names and "F2" in names:
        i, j = names.index("F1"), names.index("F2")
        th[j] = max(th[j], f2_factor * th[i] * space.scales[i] / space.scales[j])
    return space.project(th)


def scan_directions(logs: list[Anchors], space: Space, theta: np.ndarray, spans: tuple[float, ...] = (math.log(3.0), math.log(3.0) / 8),
                    points: int = 16, rounds: int = 2, cost_of: Callable[[np.ndarray], np.ndarray] | None = None) -> Polished:
    """Robust 1-D scans of the replay cost (or of ``cost_of(thetas)``) along every direction of :func:`directions_of`, ``rounds`` times.

    Each scan (coarse, then fine around the best) is one batched replay of ``points`` offsets from the current point within ``span`` (the split four
    times wider, in logit units); the best is kept. A scan sees another basin along its axis, where a local search sees only the slope: the slow logs'
    traps (``B`` folded into ``Beq``; every force and drag at a wrong common scale) lie along these axes.
    """
    theta = space.project(np.asarray(theta, dtype=float).copy())
    evaluate = cost_of or (lambda thetas: costs(logs, space, thetas))
    cost = start = float(evaluate(theta[None])[0])
    names = space.names
    for _ in range(rounds):
        for d in directions_of(names):
            for span in spans:
                coarse = span == spans[0]
                # Only the moved points are run (the current one's cost is known): 16 of them fill one compiled batch.
                if d == "split" and coarse:  # every share of B in the drag, from 1 % to 99 % (logit: log(B / Beq))
                    i, j = names.index("B"), names.index("Beq")
                    share = math.log(max(theta[i] * space.scales[i], 1e-9) / max(theta[j] * space.scales[j], 1e-9))
                    trials = np.array([moved(space, theta, d, x - share) for x in np.linspace(-4.6, 4.6, points)])
                else:
                    X = np.linspace(-span, span, points) * (4.0 if d == "split" else 1.0 if d == "scale" else 2.0)
                    trials = np.array([moved(space, theta, d, x) for x in X])
                if d == "split" and "v2" in names and coarse:
                    # B acts only below v2 and F2: the split leaves the trap "B = 0" only with a slip region the cart reaches and stays in.
                    factors = SLIP_F2_FACTORS if {"F1", "F2"} <= set(names) else (None,)
                    extra = [slip_region(space, th, v2, factor) for factor in factors for v2 in SLIP_SPEEDS for th in trials]
                    trials = np.vstack([trials, extra])
                c = evaluate(trials)
                k = int(np.argmin(c))
                if c[k] < cost:
                    theta, cost = trials[k], float(c[k])
    return Polished(theta, cost, start, rounds, 1 + rounds * len(directions_of(names)) * len(spans))  # one replay per scan


#: Pairs of parameters that trade off, moved together (diagonally) by :func:`polish`.
PAIRS = (("F2", "v2"), ("F1", "F2"), ("Beq", "force_gain"))


def along(space: Space, theta: np.ndarray, j: int, factors: np.ndarray) -> np.ndarray:
    """``theta`` with its ``j``-th value times each of ``factors``, projected (:meth:`Space.project`): one row per factor."""
    trials = np.tile(theta, (len(factors), 1))
    trials[:, j] = theta[j] * factors
    return np.array([space.project(th) for th in trials])


def polish(logs: list[Anchors], space: Space, theta: np.ndarray, max_iter: int = 12, work: float = math.inf,
           scan: tuple[str, ...] = ("F1", "F2", "v2"), scan_spans: tuple[float, ...] = (2.0, 0.15, 0.015), scan_rounds: int = 2) -> Polished:
    """A pattern search on the replay errors over the scaled parameters ``theta``.

    The replay's error is not smooth in the parameters (a breakaway that happens or not is a jump), so derivatives mislead. The thresholds ``scan``,
    whose jumps dominate, are first scanned one by one, ``scan_rounds`` times, over ``scan_spans`` (coarse then fine, 15 factors log-spaced within
    ``1 + span`` either way). Each iteration tries every parameter up and down by a relative radius (2 % at first), the four diagonal moves of each of
    :data:`PAIRS` and the last good move, in one batched replay, and keeps the best if it lowers the cost; else the radius shrinks threefold, down to
    0.1 %. Bounds hold by projection (:meth:`Space.project`). It stops once it has replayed ``work`` samples (sets x samples: fit.POLISH_WORK).
    """
    names, project = space.names, space.project
    done = {"samples": 0.0, "replays": 0}
    n_samples = sum(a.n for a in logs)

    def cost_of(thetas: np.ndarray) -> np.ndarray:
        done["samples"] += thetas.shape[0] * n_samples
        done["replays"] += 1
        return costs(logs, space, thetas)

    theta = project(np.asarray(theta, dtype=float).copy())
    cost = start_cost = float(cost_of(theta[None])[0])
    radius, it, n = 0.02, 0, len(theta)
    # Thresholds first (the docstring). (A 0.5 ms sub-step runs 3 times faster but moved the replay an encoder step: a log of steps went astray.)
    scanned = theta
    for name in [n_ for n_ in scan if n_ in names] * scan_rounds:
        j = names.index(name)
        for span in scan_spans:
            if done["samples"] > work:
                break
            trials = along(space, scanned, j, exact.exp(np.linspace(-math.log1p(span), math.log1p(span), 15)))
            scanned = trials[int(np.argmin(cost_of(trials)))]
    if scanned is not theta and (c := float(cost_of(scanned[None])[0])) < cost:
        theta, cost = scanned, c
    momentum, E = np.zeros(n), np.eye(n)
    pairs = [(names.index(a), names.index(b)) for a, b in PAIRS if a in names and b in names]
    for it in range(1, max_iter + 1):
        if done["samples"] > work:
            break
        size = radius * np.maximum(np.abs(theta), 1e-2)
        diagonal = [si * size[i] * E[i] + sj * size[j] * E[j] for i, j in pairs for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1))]
        trials = np.array([project(theta + m) for m in np.vstack([np.diag(size), -np.diag(size), *diagonal, momentum])])
        tried = cost_of(trials)
        best = int(np.argmin(tried))
        if tried[best] < cost * (1 - 1e-6):
            momentum = trials[best] - theta
            theta, cost = trials[best], float(tried[best])
        else:
            momentum = np.zeros(n)
            radius /= 3.0
            if radius < 1e-3:
                break
    return Polished(theta=theta, cost=cost, start_cost=start_cost, iterations=it, replays=done["replays"])


#: The slip region's corner: the cart leaves at drive ``F2`` or speed ``v2``, whichever first, so the cost runs in a narrow valley along the pair.
PARTNERS = {"F2": "v2", "v2": "F2"}
#: How far (log) a partner is scanned: a force finely, a speed widely (along the corner 1 % of ``F2`` is worth about 12 % of ``v2``).
PARTNER_SPANS = {"F2": 0.03, "v2": 0.3}


def valley(logs: list[Anchors], space: Space, thetas: np.ndarray, moved_names: Sequence[str], coarse: int = 16, fine: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``thetas``, the best value of its threshold's :data:`PARTNERS` (the others held).

    ``moved_names[i]`` is the threshold that row ``i`` moved; its partner is scanned over ``coarse`` log offsets within :data:`PARTNER_SPANS` either
    way, then over ``fine`` between the best one's neighbours (a valley a few tenths of a per cent wide lies between two coarse points, and the cost
    falls towards it). Two batched replays, of whole batches of 16 for an even number of rows. Returns the best costs ``(m,)`` and thetas ``(m, n)``.
    """
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    m = thetas.shape[0]
    k = np.array([space.names.index(PARTNERS[name]) for name in moved_names])
    spans = np.array([PARTNER_SPANS[PARTNERS[name]] for name in moved_names])
    grid = np.linspace(-1.0, 1.0, coarse)[None, :] * spans[:, None]  # (m, coarse), log offsets
    h = spans * 2.0 / (coarse - 1)

    def trials(offsets: np.ndarray) -> np.ndarray:  # each row's partner moved by each of its offsets
        return np.vstack([along(space, theta, j, exact.exp(o)) for theta, j, o in zip(thetas, k, offsets)])

    T1 = trials(grid)
    c1 = costs(logs, space, T1).reshape(m, coarse)
    centre = grid[np.arange(m), np.argmin(c1, axis=1)]
    T2 = trials(centre[:, None] + np.linspace(-1.0, 1.0, fine)[None, :] * h[:, None])
    c = np.c_[c1, costs(logs, space, T2).reshape(m, fine)]
    T = np.concatenate([T1.reshape(m, coarse, -1), T2.reshape(m, fine, -1)], axis=1)
    best = np.argmin(c, axis=1)
    return c[np.arange(m), best], T[np.arange(m), best]


#: Log-offsets of ``v2`` that :func:`walk` tries, each with its best ``F2``.
WALK_OFFSETS = (-0.1, -0.06, -0.03, 0.03, 0.06, 0.1)


def walk(logs: list[Anchors], space: Space, theta: np.ndarray, cost: float) -> tuple[np.ndarray, float]:
    """Along the slip region's corner from ``theta`` (cost ``cost``): the best :data:`WALK_OFFSETS` of ``v2`` (each with its :func:`valley` ``F2``).

    A pattern search stops anywhere on the corner's valley floor (each of its moves leaves it); the floor may fall away from there. Returns the best
    point and its cost (``theta`` and ``cost`` if none is lower).
    """
    if "v2" not in space.names or "F2" not in space.names:
        return theta, cost
    rows = np.tile(theta, (len(WALK_OFFSETS), 1))
    rows[:, space.names.index("v2")] *= exact.exp(np.array(WALK_OFFSETS))
    c, T = valley(logs, space, rows, ["v2"] * len(rows))
    best = int(np.argmin(c))
    return (T[best], float(c[best])) if c[best] < cost else (theta, cost)


#: The local evolution strategy (:func:`evolve`): its first step (log units), generations and population (one compiled batch per generation).
EVOLVE_SIGMA = 0.02
EVOLVE_GENERATIONS = 40
EVOLVE_POPULATION = 16
#: :func:`evolve` stops once its step is under STALL_STEP of its first and its best fell less than STALL_GAIN in STALL_GENERATIONS generations (runs
#: settled by generation 80-160 then lowered it 1e-5); not on cost alone (a later winner kept its best 20 generations, step 0.25-0.36).
STALL_GENERATIONS = 25
STALL_GAIN = 1e-3
STALL_STEP = 1 / 30
#: :func:`evolve`'s samples are rounded to this many decimals (log units) before they are replayed and told: numpy's products (OpenBLAS, its kernels
#: chosen by CPU) move them in their last bits, and a sample rounded the other way sends the search elsewhere. A run draws some 22400 coordinates,
#: some 1e-16 apart with its state rounded too (:func:`_canonical_state`): at 1e-9 about one run in a hundred meets a boundary. Not coarser: the
#: covariance's narrow axes step 1e-6 late in a run (at 1e-6 the corpus met the bar on 17 of 22 cases instead of 22).
SAMPLE_DECIMALS = 9
#: The covariance is rounded to this share of ``sqrt(C_ii C_jj)`` before its eigen-decomposition (:func:`_covariance_eigh`).
COVARIANCE_GRID = 2.0**-30


def _covariance_eigh(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CMA-ES's ``CMA_eigenmethod``: :func:`exact.eigh` of ``C`` rounded, with the same signs and bits on any CPU (LAPACK flips columns)."""
    return exact.eigh(_rounded_covariance(C))


def _rounded_covariance(C: np.ndarray) -> np.ndarray:
    """``C`` (symmetric) on a grid of a power of two near ``sqrt(C_ii C_jj) * COVARIANCE_GRID``: dividing by it and multiplying back add no bits."""
    C = np.asarray(C, dtype=float)
    grid = np.ldexp(1.0, np.frexp(np.sqrt(np.outer(np.diag(C), np.diag(C))) * COVARIANCE_GRID)[1])
    rounded = np.round(C / grid) * grid
    return np.triu(rounded) + np.triu(rounded, 1).T


def _canonical_state(es) -> None:
    """CMA-ES's state rounded after each generation (pycma's products go through OpenBLAS): its mean (9 decimals, log units), step (9 digits),
    evolution paths (``ps`` 6 decimals, ``pc`` 7 digits) and covariance (:func:`_rounded_covariance`). Unrounded, their last bits grew with the
    covariance's condition (to 1e-11 in ``ps`` at 6e6) until a generation sampled elsewhere."""
    es.mean = np.round(np.asarray(es.mean, dtype=float), 9)
    es.sigma = exact.significant(float(es.sigma), 9)
    es.adapt_sigma.ps = np.round(np.asarray(es.adapt_sigma.ps, dtype=float), 6)
    es.pc = exact.significant(np.asarray(es.pc, dtype=float), 7)
    es.sm.C = _rounded_covariance(es.sm.C)


def evolve(logs: list[Anchors], space: Space, theta: np.ndarray, cost: float, seed: int = 19, sigma: float = EVOLVE_SIGMA,
           generations: int = EVOLVE_GENERATIONS, give_up: tuple[int, float] | None = None) -> tuple[np.ndarray, float]:
    """CMA-ES (:mod:`cma`) on the replay cost around ``theta`` (cost ``cost``), in log coordinates from a step ``sigma``, at most ``generations`` of
    :data:`EVOLVE_POPULATION` or until it stalls (:data:`STALL_GENERATIONS`); ``give_up=(g, c)``: stop at generation ``g`` with no cost below ``c``.

    Derivative-free with a population per step, it steps over the replay cost's small jumps and learns the joint moves the pattern search's fixed
    directions miss. Seeded and rounded (:data:`SAMPLE_DECIMALS`, :func:`_canonical_state`, :func:`_covariance_eigh`) so that CPUs' last bits do not
    change what is replayed; numpy's global random state is restored. Returns the best point and its cost (``theta`` and ``cost`` if none is lower).
    """
    import cma

    state = np.random.get_state()
    try:
        options = {"popsize": EVOLVE_POPULATION, "seed": seed, "verbose": -9, "maxiter": generations, "tolx": 1e-4,
                   "CMA_eigenmethod": _covariance_eigh}
        es = cma.CMAEvolutionStrategy(list(exact.log(np.maximum(theta, 1e-12))), sigma, options)
        best_by_generation = []
        while not es.stop():
            U = np.round(np.array(es.ask()), SAMPLE_DECIMALS)
            es.tell(list(U), list(costs(logs, space, np.array([space.project(exact.exp(u)) for u in U]))))
            _canonical_state(es)
            best_by_generation.append(float(es.result.fbest))
            if give_up and es.countiter >= give_up[0] and es.result.fbest >= give_up[1]:
                break
            if (es.sigma < STALL_STEP * sigma and len(best_by_generation) > STALL_GENERATIONS
                    and best_by_generation[-1] >= (1 - STALL_GAIN) * best_by_generation[-1 - STALL_GENERATIONS]):
                break
        best, best_cost = space.project(exact.exp(np.asarray(es.result.xbest))), float(es.result.fbest)
    finally:
        np.random.set_state(state)
    return (best, best_cost) if best_cost < cost else (theta, cost)


# ---------------------------------------------------------------------- what the replay says back
#: Log-offsets of the profile (each side): 0.3 % to a factor 2.
PROFILE_OFFSETS = (0.003, 0.01, 0.03, 0.1, 0.3, 0.7)
DETERMINED, BOUNDED, NOT_IDENTIFIED = "determined", "bounded", "not identified"
#: The friction law's thresholds: the replay cost is a staircase in each (see :func:`profile`).
THRESHOLDS = ("F1", "v1", "F2", "v2")
#: A parameter's range (:class:`Profile` ``allowed``) is where the replay cost stays below this many times the answer's: the corpus's true values
#: replay at up to 1.64 times the answer's cost (quantization and noise), and wider ranges say nothing (slow ramps: F1's reaches 0 at 3 times).
RANGE_COST_RATIO = 2.0
#: Uncertain by over this share of its value, a parameter is only bounded: the unseen rig's random steps had F1 15 % off "determined" to 30 %.
MAX_RELATIVE_SIGMA = 0.2


@dataclass(frozen=True)
class Profile:
    """Per parameter: status, uncertainty (scaled; inf unless determined) and allowed range ``(low, high)`` (scaled; 0/inf: no rise)."""

    status: tuple[str, ...]
    sigma: np.ndarray
    allowed: tuple[tuple[float, float], ...]
    threshold: float
    correlation: float


def correlation_length(residuals: np.ndarray, sizes: list[int]) -> float:
    """``1 + 2 sum(autocorrelation)`` up to its first zero, sample-weighted over the logs (>= 1).

    A replay's errors come in runs (a breakaway a millisecond late is off for a while), so ``N`` errors hold about ``N / k`` independent ones.
    """
    lengths, weights = [], []
    for e in np.split(residuals, np.cumsum(sizes)[:-1]):
        e = e - e.mean()
        if e.size < 4 or not np.any(e):
            continue
        spectrum = np.fft.rfft(e, 2 * e.size)
        acf = np.fft.irfft(spectrum * np.conj(spectrum))[: e.size]
        acf = acf / acf[0]
        stop = int(np.argmax(acf <= 0)) if np.any(acf <= 0) else e.size
        lengths.append(1.0 + 2.0 * float(np.sum(acf[1:stop])))
        weights.append(e.size)
    return max(1.0, float(np.average(lengths, weights=weights))) if lengths else 1.0


def stretch_of(logs: list[Anchors]) -> np.ndarray:
    """For each replay error (in the order of :func:`replay_errors`), the index of its stretch between restarts.

    Examples
    --------
    >>> a = Anchors(np.zeros(5), np.arange(5.0), np.zeros((5, 1)), np.ones(1), np.zeros(4), {3: np.zeros(4)}, np.array([0, 3]))
    >>> stretch_of([a, a]).tolist()
    [0, 0, 0, 1, 1, 2, 2, 2, 3, 3]
    """
    out, offset = [], 0
    for a in logs:
        out.append(offset + np.searchsorted(a.segments, np.repeat(np.arange(a.n), a.measured.shape[1]), side="right") - 1)
        offset += len(a.segments)
    return np.concatenate(out)


def profile(logs: list[Anchors], space: Space, theta: np.ndarray, step: float = 3e-3) -> Profile:
    """The replay cost along each parameter (the others held), and along the joint directions, both ways.

    Each parameter and joint direction (:func:`directions_of`) is moved by :data:`PROFILE_OFFSETS` both ways (log units; four times those, in logit
    units, for the split). The threshold is one effective chi-square unit, ``k s^2`` (``s^2`` the answer's mean squared weighted error, ``k`` its
    :func:`correlation_length`), at least a stretch's mean cost. A side where the cost crosses it bounds the move (interpolated; for
    :data:`THRESHOLDS` the first offset above). Crossed both ways, the parameter is determined, uncertain by the larger half-width, at least the
    linearized covariance (central differences, relative ``step``) and its change along a joint direction's half-width. A joint direction open on a
    side leaves none of its members determined: a slow log never showing the inertia cannot tell the gain from a common scale of everything. ``F2``
    and ``v2`` (:data:`PARTNERS`) count, from the first offset above the threshold on, the move with the other's best value (:func:`valley`).

    No uncertainty is below the finest offset, nor a threshold's below the distance to its range's farther end (at 100 Hz F1 5.6 % off was "known" to
    0.3 %). The ranges (``allowed``) are where the cost stays below :data:`RANGE_COST_RATIO` times the answer's, along the parameter and its joint
    directions. Uncertain by more than :data:`MAX_RELATIVE_SIGMA` of its value, or with a range open on a side, a parameter is only bounded.
    """
    n = len(theta)
    offsets = np.array(PROFILE_OFFSETS)
    joint = [d for d in directions_of(space.names) if d in ("scale", "split")]
    widths = {d: 4.0 if d == "split" else 1.0 for d in joint}
    trials = [theta] + [np.where(np.arange(n) == j, theta[j] * math.exp(sign * o), theta) for j in range(n) for sign in (1.0, -1.0) for o in offsets]
    for d in joint:
        trials += [moved(space, theta, d, sign * o * widths[d]) for sign in (1.0, -1.0) for o in offsets]
    size = step * np.abs(theta)
    trials += list(theta + np.diag(size)) + list(theta - np.diag(size))
    R = np.nan_to_num(replay_errors(logs, space.vectors(np.clip(np.array(trials), space.lower, space.upper)), space.inputs), nan=1e6)
    costs = np.einsum("ij,ij->i", R, R)
    r0, cost0 = R[0], float(costs[0])
    k = correlation_length(r0, [a.measured.size for a in logs])
    # At least a stretch's worth of cost: a replay's errors correlate beyond their autocorrelation (a threshold crossed or not shifts a stretch).
    threshold = max(k * cost0 / r0.size, cost0 / sum(len(a.restarts) + 1 for a in logs))
    m = len(offsets)
    chains = []  # F2 and v2 (PARTNERS): the move with the partner's best value, one batched replay per round
    for j, name in enumerate(space.names):
        if name in PARTNERS and PARTNERS[name] in space.names:
            for side in range(2):
                first = 1 + 2 * j * m + side * m
                above = np.flatnonzero(costs[first : first + m] > cost0 + threshold)
                if above.size:
                    chains.append((j, first + int(above[0]), first + m))
    while chains:
        found, _ = valley(logs, space, np.array([trials[i] for _, i, _ in chains]), [space.names[j] for j, _, _ in chains])
        costs[[i for _, i, _ in chains]] = np.minimum(costs[[i for _, i, _ in chains]], found)
        chains = [(j, i + 1, end) for (j, i, end), c in zip(chains, found) if c <= cost0 + threshold and i + 1 < end]

    def reach(first: int, staircase: bool = False, rise: float = threshold) -> tuple[float, float]:
        """How far (offset units) the cost stays below ``cost0 + rise`` up and down, from trial ``first`` (see above)."""
        out = []
        for side in range(2):
            c = costs[first + side * m : first + (side + 1) * m]
            above = np.flatnonzero(c > cost0 + rise)
            if not above.size:
                out.append(math.inf)
                continue
            i = int(above[0])
            lo_o, lo_c = (0.0, cost0) if i == 0 else (offsets[i - 1], max(c[i - 1], cost0))
            out.append(offsets[i] if staircase else lo_o + (offsets[i] - lo_o) * (cost0 + rise - lo_c) / max(c[i] - lo_c, 1e-300))
        return out[0], out[1]

    wide = max(threshold, (RANGE_COST_RATIO - 1.0) * cost0)
    status, sigma, allowed = [], np.full(n, math.inf), []
    for j in range(n):
        up, down = reach(1 + 2 * j * m, space.names[j] in THRESHOLDS, wide)
        allowed.append((theta[j] * math.exp(-down) if math.isfinite(down) else 0.0, theta[j] * math.exp(up) if math.isfinite(up) else math.inf))
        up, down = reach(1 + 2 * j * m, space.names[j] in THRESHOLDS)
        status.append((NOT_IDENTIFIED, BOUNDED, DETERMINED)[math.isfinite(up) + math.isfinite(down)])  # by the sides bounded
        if status[j] == DETERMINED:
            sigma[j] = abs(theta[j]) * (math.exp(max(up, down)) - 1)
    determined = [j for j in range(n) if status[j] == DETERMINED]
    base = 1 + 2 * n * m + 2 * m * len(joint)
    if determined:
        J = ((R[base : base + n] - R[base + n : base + 2 * n]) / (2 * size[:, None])).T[:, determined]
        inverse = exact.lstsq(exact.dot(J.T, J), np.eye(len(determined)))  # times the threshold: the linearized covariance
        # Cluster-robust (sandwich) covariance, the stretches between restarts as clusters: a replay's errors within a stretch share one cause (a
        # breakaway early or late, a restart's state), and the model's own errors pull each stretch its own way.
        clusters = stretch_of(logs)
        scores = np.zeros((int(clusters.max()) + 1, len(determined)))
        np.add.at(scores, clusters, J * r0[:, None])
        S = scores.shape[0]
        robust = exact.dot(exact.dot(inverse, exact.dot(scores.T, scores)), inverse) * (S / max(S - len(determined), 1))
        sigma[determined] = np.maximum(sigma[determined], np.sqrt(np.clip(np.maximum(np.diag(inverse * threshold), np.diag(robust)), 0.0, None)))
    for i, d in enumerate(joint):
        up, down = reach(1 + 2 * n * m + 2 * i * m)
        ends = [moved(space, theta, d, x * widths[d]) for x in (up, -down) if math.isfinite(x)]
        # A member's range covers the joint move's too: moved alone it may be pinned where moved with the others it is not (slow ramps on the unseen
        # rig: the common scale 8.7 % low, F1 and the gain bounded to a few tenths of a per cent).
        sides = [(x, sign) for x, sign in zip(reach(1 + 2 * n * m + 2 * i * m, rise=wide), (1.0, -1.0))]
        for j, name in enumerate(space.names):
            if name not in (SCALED if d == "scale" else ("B", "Beq")):
                continue
            low, high = allowed[j]
            for x, sign in sides:
                if math.isfinite(x):
                    end = moved(space, theta, d, sign * x * widths[d])[j]
                    low, high = min(low, end), max(high, end)
                elif moved(space, theta, d, sign * widths[d] * offsets[-1])[j] > theta[j]:  # never bounded this way: no end
                    high = math.inf
                else:
                    low = 0.0
            allowed[j] = (low, high)
            if status[j] == DETERMINED and len(ends) == 2:
                sigma[j] = max(sigma[j], max(abs(e[j] - theta[j]) for e in ends))
            elif status[j] == DETERMINED:  # the joint move is not bounded both ways: neither is this parameter
                status[j], sigma[j] = BOUNDED, math.inf
    for j in [i for i in range(n) if status[i] == DETERMINED]:
        if space.names[j] in THRESHOLDS and 0.0 < allowed[j][0] <= allowed[j][1] < math.inf:
            # A staircase: its first step up says little of where the cost stays low (the docstring; RANGE_COST_RATIO).
            sigma[j] = max(sigma[j], theta[j] - allowed[j][0], allowed[j][1] - theta[j])
        # Not below the finest offset or the Jacobian's step, below which nothing is measured (the sticky rig's chirp: Beq 0.3 % off, said 0.1 %).
        sigma[j] = max(sigma[j], abs(theta[j]) * max(math.expm1(offsets[0]), step))
        # Open range: the cost rises a little, then stays within RANGE_COST_RATIO to 0 or infinity (the light rig's random steps: F1 71 % high).
        if sigma[j] > MAX_RELATIVE_SIGMA * abs(theta[j]) or not 0.0 < allowed[j][0] <= allowed[j][1] < math.inf:
            status[j], sigma[j] = BOUNDED, math.inf
    return Profile(tuple(status), sigma, tuple(allowed), threshold, k)
