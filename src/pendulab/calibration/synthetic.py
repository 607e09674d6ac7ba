"""Synthetic logs with known parameters: the fit's test corpus (used by ``tests/`` and ``bench/``).

Each log is the CasADi plant under the *true* switching stick-slip law driven by a voltage profile, then position noise and the encoder's
quantization, as a rig would log it; optionally noise on the logged voltage. The corpus (:func:`corpus`) crosses :data:`SHAPES` with :data:`RIGS` and
two voltage-noise levels, and holds a seeded third of the cases out (:func:`held_out`): those are looked at only at the end and reported apart.

Examples
--------
>>> log = synthetic_log("triangle", RIGS["sticky"], duration=4.0, voltage_noise=0.0)
>>> round(log.duration, 1), bool(abs(log.x[0]) < 1e-4)
(4.0, True)
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from pendulab import exact
from pendulab.calibration.logs import RampLog
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import PlantModel

#: Sample period of the synthetic logs (s).
STEP = 1e-3
#: Rigs spread over a wide box around the lab's defaults (Beq 4.3, force gain 1, F1 1.5 N, B 20).
RIGS = {
    "unseen": PlantParameters.preset("none", Beq=6.1, force_gain=0.82, F1=2.3, v1=0.003, F2=3.9, v2=0.06, B=60.0),
    "heavy drag, weak drive": PlantParameters.preset("none", Beq=12.0, force_gain=0.6, F1=1.0, v1=0.004, F2=2.0, v2=0.08, B=40.0),
    "light drag, strong drive": PlantParameters.preset("none", Beq=3.0, force_gain=1.2, F1=0.8, v1=0.006, F2=1.6, v2=0.04, B=15.0),
    "sticky": PlantParameters.preset("none", Beq=8.0, force_gain=0.9, F1=3.0, v1=0.002, F2=5.0, v2=0.03, B=100.0),
}
TRUE = RIGS["unseen"]
#: A plausible rig unlike the lab's defaults (the cart alone): what tests and benchmarks extract or fit back.
TEST_RIG = PlantParameters.preset("none", Beq=5.2, force_gain=0.9, F1=2.0, v1=0.004, F2=3.6, v2=0.06, B=25.0)
#: Shapes of the corpus (:func:`corpus_log`).
SHAPES = ("ramps with holds", "triangle", "random steps", "chirp", "closed loop", "calibrate ramp")
#: Voltage noise levels of the corpus (V).
VOLTAGE_NOISE = (0.0, 0.01)


def voltage_profile(shape: str, duration: float, seed: int = 0, period: float = STEP) -> np.ndarray:
    """Voltage samples (one per ``period``) of an open-loop shape.

    ``"ramps with holds"``: slow ramps to 1.2-3 V, held 0.6 s, down, rest, both ways; ``"ramps with rests"``: to 2.5-4 V, dropped at the peak;
    ``"triangle"``: 0.4 Hz, 3 V; ``"random steps"``: random size and sign, some below the breakaway; ``"chirp"``: 0.3 to 3 Hz with a slow offset.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration / period))) * period
    if shape in ("ramps with holds", "ramps with rests"):  # a ramp from 0 V each way in turn, a rest between
        hold = 0.6 if shape == "ramps with holds" else 0.0  # held at the peak then down; else (faster, higher) dropped to 0 at the peak
        start, margin, peaks, rests = (0.3, 1.0, (1.2, 3.0), (0.4, 0.8)) if hold else (0.5, 2.0, (2.5, 4.0), (0.6, 1.2))
        V, sign = np.zeros_like(t), 1.0
        while start < duration - margin:
            rise, peak = rng.uniform(0.8, 1.6), rng.uniform(*peaks)
            up = (t >= start) & (t < start + rise)
            V[up] = sign * peak * (t[up] - start) / rise
            if hold:
                held = (t >= start + rise) & (t < start + rise + hold)
                V[held] = sign * peak
                down = (t >= start + rise + hold) & (t < start + 2 * rise + hold)
                V[down] = sign * peak * (1 - (t[down] - start - rise - hold) / rise)
            start += (2 * rise + hold if hold else rise) + rng.uniform(*rests)
            sign = -sign
        return V
    if shape == "triangle":
        return 3.0 * (4 * np.abs((0.4 * t) % 1.0 - 0.5) - 1)  # 0.4 Hz
    if shape == "random steps":
        edges = np.cumsum(rng.uniform(0.25, 0.6, size=int(duration / 0.25) + 2))
        levels = rng.choice([-1.0, 1.0], size=edges.size) * rng.uniform(0.5, 3.5, size=edges.size)
        levels[::3] = 0.0
        return levels[np.clip(np.searchsorted(edges, t), 0, levels.size - 1)]
    if shape == "chirp":
        f = 0.3 + (3.0 - 0.3) * t / duration
        return 3.0 * exact.sin(2 * np.pi * np.cumsum(f) * period) + 0.4 * exact.sin(2 * np.pi * 0.1 * t)  # the same log on any CPU (pendulab.exact)
    raise ValueError(f"unknown open-loop shape {shape!r}; choose among ramps with holds, ramps with rests, triangle, random steps, chirp")


def _measured(t: np.ndarray, V: np.ndarray, x: np.ndarray, q: float, noise: float, voltage_noise: float, seed: int,
              source: str, alpha: np.ndarray | None = None) -> RampLog:
    """The log as a rig writes it: position noise then the encoder's quantization, voltage noise (``seed``'s draws)."""
    rng = np.random.default_rng(seed)
    x = x + rng.normal(0.0, noise, x.size) if noise > 0 else x.copy()
    x = q * np.round(x / q) if q > 0 else x
    V = V + rng.normal(0.0, voltage_noise, V.size) if voltage_noise > 0 else V.copy()
    return RampLog(t, V, x, alpha=alpha, source=source)


def _frozen(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """``arrays`` made read-only: a cached run is shared by every log made from it (:func:`_measured` copies)."""
    for array in arrays:
        array.flags.writeable = False
    return arrays


#: The runs behind the synthetic logs are cached in the process (about 0.1 ms of Python per sample; tests and the corpus ask for each several times).
RUNS_CACHED = 64


def synthetic_log(shape: str, params: PlantParameters = TRUE, duration: float = 20.0, *, noise: float = 1e-5,
                  voltage_noise: float = 0.01, seed: int = 0, cart_hold: float = 0.35, period: float = STEP) -> RampLog:
    """A log of an open-loop ``shape`` (:func:`voltage_profile`) on the rig ``params``, sampled every ``period`` (the drive held over each sample).

    A slow outer loop keeps the cart on its track: the profile is added to a weak position feedback (blocks of 0.1 s, as a TA would).
    """
    V, x = _open_loop_run(shape, params, float(duration), seed, cart_hold, float(period))
    return _measured(np.arange(x.size) * period, V, x, params.q_x, noise, voltage_noise, seed + 100, f"synthetic {shape}")


@lru_cache(maxsize=RUNS_CACHED)
def _open_loop_run(shape: str, params: PlantParameters, duration: float, seed: int, cart_hold: float, period: float) -> tuple[np.ndarray, ...]:
    """:func:`synthetic_log`'s run: the voltage (0 after the last step) and the cart's position at each sample."""
    V_plan = voltage_profile(shape, duration, seed, period)
    n = V_plan.size
    states = np.zeros((n + 1, 4))
    V = np.empty(n)
    block = int(round(0.1 / period))
    for i in range(0, n, block):
        x = states[i, 0]
        V[i : i + block] = np.clip(V_plan[i : i + block] - 20.0 * x * (abs(x) > cart_hold * 0.5), -params.V_max, params.V_max)
        part = PlantModel().simulate(params, V[i : i + block], period, states[i], t0=i * period)
        states[i : i + part.shape[0]] = part
    return _frozen(np.append(V, 0.0), states[:, 0].copy())


def closed_loop_params(rig: PlantParameters = TRUE) -> PlantParameters:
    """The long pendulum on ``rig``'s cart friction, poked at 1 s."""
    friction = {n: getattr(rig, n) for n in ("F1", "v1", "F2", "v2", "B", "Beq", "force_gain")}
    return PlantParameters.preset("long", poke_magnitude=150.0, poke_duration=0.005, poke_start=1.0, **friction)


def closed_loop_log(rig: PlantParameters = TRUE, duration: float = 8.0, *, noise: float = 1e-5, voltage_noise: float = 0.0, seed: int = 0) -> RampLog:
    """A closed-loop run with the long pendulum up: the demo controller through the FMUs, poked at 1 s.

    The angle and position are quantized as the encoders give them; the voltage is the applied one.
    """
    t, V, x, alpha = _closed_loop_run(rig, float(duration))
    return _measured(t.copy(), V, x, closed_loop_params(rig).q_x, noise, voltage_noise, seed, "synthetic closed loop, long pendulum",
                     alpha=alpha.copy())


@lru_cache(maxsize=RUNS_CACHED)
def _closed_loop_run(rig: PlantParameters, duration: float) -> tuple[np.ndarray, ...]:
    """:func:`closed_loop_log`'s run: time, voltage, position and measured angle."""
    from pendulab.control.controller import demo_controller
    from pendulab.simulation import simulate
    from pendulab.spec import RunSpec, Timing

    c = simulate(RunSpec.for_parameters(demo_controller("long"), closed_loop_params(rig), timing=Timing(stop_time=duration))).columns
    return _frozen(*(np.array(c[k], dtype=float) for k in ("t", "voltage", "x", "alpha_measured")))


def calibrate_ramp_log(rig: PlantParameters = TRUE, *, iterations: int = 1, noise: float = 1e-5, voltage_noise: float = 0.0, seed: int = 0) -> RampLog:
    """The ``pendulab calibrate`` ramp test, run by the same program on the virtual rig with ``rig``."""
    t, V, x = _calibrate_ramp_run(rig, iterations)
    return _measured(t.copy(), V, x, rig.q_x, noise, voltage_noise, seed, "synthetic calibrate ramp test")


@lru_cache(maxsize=RUNS_CACHED)
def _calibrate_ramp_run(rig: PlantParameters, iterations: int) -> tuple[np.ndarray, ...]:
    """:func:`calibrate_ramp_log`'s run: time, voltage and position as the ramp test logged them."""
    from pendulab.calibration.ramp import run_ramp_test
    from pendulab.calibration.rig import VirtualRig

    with VirtualRig(rig) as virtual:
        log = run_ramp_test(virtual, iterations=iterations)
    return _frozen(*(np.array(a, dtype=float) for a in (log.t, log.V, log.x)))


@dataclass(frozen=True)
class Case:
    """One corpus case: a shape on a rig (16 s of it, the closed loop 8 s), with or without voltage noise."""

    shape: str
    rig: str
    voltage_noise: float

    @property
    def name(self) -> str:
        return f"{self.shape} | {self.rig} | {self.voltage_noise * 1e3:.0f} mV"

    @property
    def params(self) -> PlantParameters:
        """The true parameters of the log (the long pendulum on the rig's cart for the closed loop)."""
        return closed_loop_params(RIGS[self.rig]) if self.shape == "closed loop" else RIGS[self.rig]

    def log(self) -> RampLog:
        if self.shape == "closed loop":
            return closed_loop_log(RIGS[self.rig], voltage_noise=self.voltage_noise)
        if self.shape == "calibrate ramp":
            return calibrate_ramp_log(RIGS[self.rig], voltage_noise=self.voltage_noise)
        return synthetic_log(self.shape, RIGS[self.rig], duration=16.0, voltage_noise=self.voltage_noise)


def corpus() -> list[Case]:
    """Every case: :data:`SHAPES` x :data:`RIGS` x :data:`VOLTAGE_NOISE`."""
    return [Case(s, r, v) for s in SHAPES for r in RIGS for v in VOLTAGE_NOISE]


def held_out(cases: list[Case], seed: int = 19) -> set[str]:
    """Names of a seeded third of ``cases``: looked at only at the end, reported apart."""
    return {cases[i].name for i in np.random.default_rng(seed).choice(len(cases), len(cases) // 3, replace=False)}
