"""Synthetic logs of shapes the fit's own code never generates, with known parameters (tests, bench).

Each is the CasADi plant under the *true* switching stick-slip law replaying a voltage profile, then
noise and encoder quantization, as a rig would log it.
"""

from __future__ import annotations

import numpy as np

from pendulab.calibration._simulation import simulate
from pendulab.calibration.logs import RampLog
from pendulab.model.parameters import PlantParameters

#: Parameters the project's defaults have never seen.
TRUE = PlantParameters.preset("none", Beq=6.1, force_gain=0.82, F1=2.3, v1=0.003, F2=3.9, v2=0.06, B=60.0)
STEP = 1e-3
#: Rigs far from the lab's defaults (Beq 4.3, force gain 1, F1 1.5 N, B 20), for the start and the benches.
RIGS = {
    "unseen": TRUE,
    "heavy drag, weak drive": PlantParameters.preset("none", Beq=12.0, force_gain=0.6, F1=1.0, v1=0.004, F2=2.0, v2=0.08, B=40.0),
    "light drag, strong drive": PlantParameters.preset("none", Beq=3.0, force_gain=1.2, F1=0.8, v1=0.006, F2=1.6, v2=0.04, B=15.0),
    "sticky": PlantParameters.preset("none", Beq=8.0, force_gain=0.9, F1=3.0, v1=0.002, F2=5.0, v2=0.03, B=100.0),
}


def voltage_profile(shape: str, duration: float, seed: int = 0) -> np.ndarray:
    """Voltage samples (one per STEP) of a test shape."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration / STEP))) * STEP
    if shape == "ramps with rests":  # slow ramps to varied peaks, both directions, rests between
        V = np.zeros_like(t)
        start, sign = 0.5, 1.0
        while start < duration - 2.0:
            rise = rng.uniform(0.8, 1.6)
            peak = rng.uniform(2.5, 4.0)
            k = (t >= start) & (t < start + rise)
            V[k] = sign * peak * (t[k] - start) / rise
            start += rise + rng.uniform(0.6, 1.2)
            sign = -sign
        return V
    if shape == "fast steps":  # steps of random size and sign, some below the breakaway
        V = np.zeros_like(t)
        edges = np.cumsum(rng.uniform(0.25, 0.6, size=int(duration / 0.25) + 2))
        levels = rng.choice([-1.0, 1.0], size=edges.size) * rng.uniform(0.5, 3.5, size=edges.size)
        levels[::3] = 0.0
        idx = np.searchsorted(edges, t)
        return levels[np.clip(idx, 0, levels.size - 1)]
    if shape == "sine sweep":  # 0.3 Hz to 3 Hz, 3 V, with an offset that changes sign
        f = 0.3 + (3.0 - 0.3) * t / duration
        phase = 2 * np.pi * np.cumsum(f) * STEP
        return 3.0 * np.sin(phase) + 0.4 * np.sin(2 * np.pi * 0.1 * t)
    raise ValueError(shape)


def synthetic_log(shape: str, params: PlantParameters = TRUE, duration: float = 20.0, *, noise: float = 1e-5,
                  voltage_noise: float = 0.01, seed: int = 0, cart_hold: float = 0.35) -> RampLog:
    """A log of ``shape``: positions noisy and quantized; the logged voltage with a little noise.

    The voltage is what was applied; the log records it with ``voltage_noise`` (V) of measurement noise.
    A simple outer loop keeps the cart on the track: the profile is added to a weak position feedback.
    """
    V_plan = voltage_profile(shape, duration, seed)
    n = V_plan.size
    # Keep the cart on its track with a slow proportional pull (blocks of 0.1 s, as a TA would).
    states = np.zeros((n + 1, 4))
    V = np.empty(n)
    block = 100
    for i in range(0, n, block):
        x = states[i, 0]
        V[i : i + block] = V_plan[i : i + block] - 20.0 * x * (abs(x) > cart_hold * 0.5)
        V[i : i + block] = np.clip(V[i : i + block], -params.V_max, params.V_max)
        part = simulate(params, V[i : i + block], STEP, states[i], t0=i * STEP)
        states[i : i + part.shape[0]] = part
    rng = np.random.default_rng(seed + 100)
    x = states[: n + 1, 0] + rng.normal(0.0, noise, n + 1)
    x = params.q_x * np.round(x / params.q_x)
    t = np.arange(n + 1) * STEP
    V_logged = np.append(V, 0.0) + rng.normal(0.0, voltage_noise, n + 1)
    return RampLog(t, V_logged, x, source=f"synthetic {shape}")


def closed_loop_log(params: PlantParameters | None = None, duration: float = 8.0, *, noise: float = 1e-5, seed: int = 0) -> tuple[RampLog, PlantParameters]:
    """A closed-loop run with the long pendulum up: the demo controller through the FMUs, poked at 1 s.

    Returns the log (quantized angle and position as the encoders give them, the applied voltage) and
    the parameters it was made with (the pendulum's, the poke and the friction of :data:`TRUE`).
    """
    from pendulab.control.controller import demo_controller
    from pendulab.simulation import simulate
    from pendulab.spec import RunSpec, Timing

    friction = {n: getattr(TRUE, n) for n in ("F1", "v1", "F2", "v2", "B", "Beq", "force_gain")}
    params = params or PlantParameters.preset("long", poke_magnitude=150.0, poke_duration=0.005, poke_start=1.0, **friction)
    run = simulate(RunSpec.for_parameters(demo_controller("long"), params, timing=Timing(stop_time=duration)))
    c = run.columns
    rng = np.random.default_rng(seed)
    x = params.q_x * np.round((c["x"] + rng.normal(0.0, noise, len(c["x"]))) / params.q_x)
    return RampLog(c["t"], c["voltage"], x, alpha=c["alpha_measured"], source="synthetic closed loop, long pendulum"), params
