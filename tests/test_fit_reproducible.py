"""The fit's replay gives the same bits on any thread count (issue 19: the same answer on any x86-64 machine).

Each parameter set is replayed by one thread from start to end, in IEEE arithmetic as written (no
reassociation, no fused multiply-add: :data:`pendulab.calibration._replay.EXACT_MATH`), so neither the
OpenMP schedule nor the CPU's vector width can change a result.
"""

from __future__ import annotations

import os
import subprocess
import sys

from pendulab.calibration._replay import EXACT_MATH  # private: the replay's compiler flags are what this checks

SCRIPT = """
import hashlib, numpy as np
from pendulab.calibration._replay import replay  # private: the replay's bitwise reproducibility is what this checks
from pendulab.calibration.synthetic import RIGS, synthetic_log
log = synthetic_log("random steps", RIGS["sticky"], duration=3.0, voltage_noise=0.0)
rng = np.random.default_rng(5)
base = np.asarray(RIGS["sticky"].as_vector(), dtype=float)
sets = base * np.exp(rng.normal(0.0, 0.2, (32, base.size)))
states = replay(sets, log.V[:-1], log.t[:-1], np.zeros(4), free=("F1", "v1", "F2", "v2", "B", "Beq", "force_gain"))
assert np.all(np.isfinite(states)) and np.ptp(states[:, -1, 0]) > 1e-3  # the sets differ
print(hashlib.sha256(states.tobytes()).hexdigest())
"""


def run(threads: int) -> str:
    env = {**os.environ, "OMP_NUM_THREADS": str(threads)}
    return subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, check=True, timeout=600).stdout.strip()


def test_a_batched_replay_is_bitwise_the_same_on_one_and_two_threads():
    assert "-ffp-contract=off" in EXACT_MATH and not any("fast-math" in f and "no" not in f for f in EXACT_MATH)
    one, two = run(1), run(2)
    assert len(one) == 64 and one == two


def test_the_replay_of_many_sets_in_chunks_equals_the_plant_simulated_set_by_set():
    """The compiled replay (parameter sets batched, padded or split to the compiled widths, the log in chunks of
    500 samples, arrays passed in place) against :func:`pendulab.calibration._simulation.simulate`, the same RK4 step
    unrolled in CasADi's virtual machine one set at a time: the same states, sample by sample, for every set."""
    import numpy as np

    from pendulab.calibration._replay import CHUNK, replay  # private: the fit's replay is what this checks
    from pendulab.calibration._simulation import simulate
    from pendulab.calibration.synthetic import RIGS, synthetic_log

    log = synthetic_log("chirp", RIGS["unseen"], duration=2.2, voltage_noise=0.0)
    assert len(log) > 4 * CHUNK  # several chunks, the last one partial
    rng = np.random.default_rng(7)
    base = np.asarray(RIGS["unseen"].as_vector(), dtype=float)
    free = ("F1", "v1", "F2", "v2", "B", "Beq", "force_gain")
    for m in (3, 40):  # padded to 16, split into 32 + 8
        sets = np.tile(base, (m, 1))
        columns = [type(RIGS["unseen"]).names().index(n) for n in free]
        sets[:, columns] *= np.exp(rng.normal(0.0, 0.2, (m, len(free))))
        states = replay(sets, log.V, log.t, np.zeros(4), free=free)
        assert states.shape == (m, len(log), 4)
        for j in (0, m // 2, m - 1):
            reference = simulate(sets[j], log.V, float(log.t[1] - log.t[0]))[1:]
            assert np.max(np.abs(states[j] - reference)) < 1e-9, (m, j)
        assert np.ptp(states[:, -1, 0]) > 1e-3  # the sets differ
