"""Synthetic ramp-test logs with known parameters, encoder quantization and noise (tests, benchmarks).

Examples
--------
>>> from pendulab.model.parameters import PlantParameters
>>> log = synthetic_ramp_log(PlantParameters.preset("none", Beq=5.0), iterations=1, seed=1)
>>> log.duration > 10
True
"""

from __future__ import annotations

import numpy as np

from pendulab.calibration.logs import RampLog
from pendulab.calibration.ramp import run_ramp_test
from pendulab.calibration.rig import VirtualRig
from pendulab.model.parameters import PlantParameters

#: A plausible rig unlike the lab's defaults (the cart alone): what tests and benchmarks extract or fit back.
TEST_RIG = PlantParameters.preset("none", Beq=5.2, force_gain=0.9, F1=2.0, v1=0.004, F2=3.6, v2=0.06, B=25.0)


def synthetic_ramp_log(
    params: PlantParameters,
    iterations: int = 1,
    *,
    noise: float = 1e-5,
    seed: int = 0,
    duration: float | None = None,
    x0: float = 0.05,
    backend: str = "auto",
) -> RampLog:
    """A ramp test of the virtual rig with ``params``; position noise added before quantization.

    The rig's own encoder quantizes ``x`` (``params.q_x``); here Gaussian noise of standard deviation
    ``noise`` (m) is added to the true position and the sum is quantized again, as a real encoder
    with vibration would read it. ``duration`` repeats iterations until the log is at least that
    long and cuts it there.
    """
    rng = np.random.default_rng(seed)
    with VirtualRig(params, x0=x0, backend=backend) as rig:
        if duration is None:
            log = run_ramp_test(rig, iterations=iterations)
        else:
            log = run_ramp_test(rig, iterations=max(iterations, 1))
            while log.duration < duration:
                more = int(np.ceil(duration / max(log.duration, 1.0) * max(iterations, 1))) + 1
                log = run_ramp_test(rig, iterations=more)
            keep = log.t <= log.t[0] + duration
            log = RampLog(log.t[keep], log.V[keep], log.x[keep], source=log.source, events=log.events)
    true_x = log.x
    q = params.q_x
    noisy = true_x + rng.normal(0.0, noise, len(true_x)) if noise > 0 else true_x.copy()
    if q > 0:
        noisy = q * np.round(noisy / q)
    return RampLog(log.t, log.V, noisy, source=f"synthetic ({log.source}, noise {noise:g} m)", events=log.events)
