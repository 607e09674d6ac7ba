"""The fit's replay gives the same bits on any thread count (issue 19: the same answer on any x86-64 machine).

Each parameter set is replayed by one vector lane of one thread from start to end, in IEEE arithmetic as
written (no reassociation, no fused multiply-add: :data:`pendulab.calibration._replay.EXACT_MATH`), so
neither the OpenMP schedule nor the CPU's vector width can change a result: the replay gives the bits of
CasADi's virtual machine.
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys

import pytest

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


@pytest.mark.parametrize("stride", [1, 10])
def test_the_replay_of_many_sets_equals_the_plant_simulated_set_by_set(stride):
    """The compiled replay (parameter sets in vector lanes, a short last group, arrays passed in place) against
    :meth:`pendulab.model.plant.PlantModel.simulate`, the plant's RK4 step in CasADi's virtual machine
    one set at a time with every parameter an input: the same states, sample by sample, for every set. At 1 kHz,
    and at 100 Hz (100 sub-steps a sample, looped by the driver: unrolled, gcc took more than 5 minutes over them)."""
    import numpy as np
    from fit_helpers import simulate

    from pendulab.calibration._replay import replay  # private: the fit's replay is what this checks
    from pendulab.calibration.synthetic import RIGS, synthetic_log

    log = synthetic_log("chirp", RIGS["unseen"], duration=2.2 * stride, voltage_noise=0.0)
    log = type(log)(log.t[::stride], log.V[::stride], log.x[::stride])
    rng = np.random.default_rng(7)
    base = np.asarray(RIGS["unseen"].as_vector(), dtype=float)
    free = ("F1", "v1", "F2", "v2", "B", "Beq", "force_gain")
    for m in (3, 41):  # fewer sets than lanes; several groups and a short last one
        sets = np.tile(base, (m, 1))
        columns = [type(RIGS["unseen"]).names().index(n) for n in free]
        sets[:, columns] *= np.exp(rng.normal(0.0, 0.2, (m, len(free))))
        states = replay(sets, log.V, log.t, np.zeros(4), free=free)
        assert states.shape == (m, len(log), 4)
        for j in (0, m // 2, m - 1):
            reference = simulate(sets[j], log.V, float(log.t[1] - log.t[0]))[1:]
            assert np.max(np.abs(states[j] - reference)) < 1e-9, (m, j)
        assert np.ptp(states[:, -1, 0]) > 1e-3  # the sets differ


@pytest.mark.parametrize("observer", [0, 2])
@pytest.mark.parametrize("stride", [1, 3])
def test_every_vector_width_gives_the_bits_of_casadis_virtual_machine(observer, stride):
    """The replay (with restarts) and the observer of the position and the angle, built for 1, 2, 4 and 8 lanes
    in one group or 4 interleaved, against the same step evaluated in CasADi's virtual machine: equal bit for bit,
    for the pendulum's sines and cosines too (taken lane by lane from the C library, as the virtual machine takes them).
    A 1 kHz log, and one of 3 ms (30 sub-steps a sample). Each build is checked on the replay
    and on the observer, at each rate (two builds a case: gcc's time is most of this test's)."""
    import casadi as ca
    import numpy as np

    from pendulab.calibration import _replay  # private: the compiled replay's lanes are what this checks
    from pendulab.calibration._observer import observer_gain
    from pendulab.calibration.synthetic import RIGS, synthetic_log
    from pendulab.model.parameters import PlantParameters

    log = synthetic_log("chirp", RIGS["unseen"], duration=0.6 * stride, voltage_noise=0.0)
    log = type(log)(log.t[::stride], log.V[::stride], log.x[::stride])
    n, free = len(log), ("F1", "v1", "F2", "v2", "B", "Beq", "force_gain")
    base = np.asarray(PlantParameters.preset("long").as_vector(), dtype=float)
    sets = base * np.exp(np.random.default_rng(3).normal(0.0, 0.2, (5, base.size)))
    key, P, h = _replay._key(sets, log.t, free)
    assert key[0] == 10 * stride  # sub-steps per sample, looped by the driver
    x0 = np.array([0.0, 0.0, 0.05, 0.0])
    if observer:
        y = np.column_stack([log.x, 0.02 * np.sin(3 * log.t)])
        gain = observer_gain(60.0, log.period, outputs=2).T.ravel().copy()
        inputs = (x0, log.V, log.t, y, gain, P)
        per_sample = [log.V[None], log.t[None], y.T, ca.repmat(ca.DM(gain).reshape((4, 2)), 1, n)]
        outputs = [np.empty((5, n, 4)), np.empty((5, n, 2))]  # corrected states, predicted outputs
    else:
        r, sr = np.zeros(n), np.zeros((n, 4))
        r[200], sr[200] = 1.0, (0.01, 0.02, -0.03, 0.1)
        inputs = (x0, log.V, log.t, r, sr, P)
        per_sample = [log.V[None], log.t[None], r[None], sr.T]
        outputs = [np.empty((5, n, 4))]
    vm = _replay._in_vm(_replay._sample(*key, observer), x0, per_sample, P, h)
    for lanes, ways in ((1, 1), (4, 4)) if (observer == 0) == (stride == 1) else ((2, 4), (8, 1)):
        run = _replay._load(_replay._source(*key, observer, ways), f"pendulab_lanes_test_{observer}", ("-O2", f"-DLANES={lanes}"))
        assert run is not None, "no C compiler"
        arrays = [np.ascontiguousarray(a, dtype=float) for a in inputs]
        run(ctypes.c_int(5), ctypes.c_int(n), *map(_replay._pointer, arrays), ctypes.c_double(h), *map(_replay._pointer, outputs[::-1]))
        for got, want in zip(outputs, vm):
            assert np.all(np.isfinite(got)) and np.array_equal(got, want), (lanes, ways)


RESTARTS_SCRIPT = """
import hashlib, numpy as np
from fit_helpers import prepared  # the log's restarts as the fit makes them
from pendulab.calibration.synthetic import RIGS, synthetic_log
digest = hashlib.sha256()
for shape, rig in (("ramps with holds", "unseen"), ("random steps", "sticky"), ("chirp", "heavy drag, weak drive")):
    (a,), _ = prepared(synthetic_log(shape, RIGS[rig], duration=8.0, voltage_noise=0.01), RIGS[rig].q_x)
    assert len(a.restarts) >= 3
    for state in [a.x0, *(a.restarts[k] for k in sorted(a.restarts))]:
        digest.update(np.asarray(state).tobytes())
print(digest.hexdigest())
"""


def test_the_replays_restarts_are_bitwise_the_same_with_any_blas_kernel():
    """The restarts' states (a line through each rest's positions) that every replay of a cart log starts from: with
    OpenBLAS's kernels for this CPU and with its SSE3 ones (``OPENBLAS_CORETYPE=Prescott``). Through ``numpy.polyfit``
    they differed in their last bits on an AVX2 machine; :func:`pendulab.exact.lstsq` gives the same."""
    tests = os.path.dirname(os.path.abspath(__file__))  # for fit_helpers
    path = os.pathsep.join(filter(None, [tests, os.environ.get("PYTHONPATH", "")]))
    runs = [subprocess.run([sys.executable, "-c", RESTARTS_SCRIPT], env={**os.environ, "PYTHONPATH": path, **extra}, capture_output=True, text=True,
                           check=True, timeout=600).stdout.strip() for extra in ({}, {"OPENBLAS_CORETYPE": "Prescott"})]
    assert len(runs[0]) == 64 and runs[0] == runs[1]


FIT_SCRIPT = """
from pendulab.calibration.fit import fit_parameters
from pendulab.calibration.synthetic import RIGS, synthetic_log
from pendulab.model.parameters import PlantParameters
log = synthetic_log("random steps", RIGS["unseen"], duration=6.0, voltage_noise=0.01)
said = []
result = fit_parameters([log], PlantParameters.preset("none"), on_progress=said.append)
assert any(s.startswith("CMA-ES") for s in said), said  # the global search ran, and moved the answer
print(repr([result.values[n] for n in result.names]), repr(result.forward_rms))
"""


def test_a_fit_gives_the_same_bits_with_numpys_avx512_code_and_openblass_kernels_switched():
    """numpy's exp, log, sin and power take code of their own on a CPU with AVX-512 and the C library's elsewhere,
    whose last bits differ (:mod:`pendulab.exact`). Through numpy, a 6 s log of random steps fitted values ~1e-8
    apart here (an AVX-512 machine), and a 16 s log of slow ramps Beq 5.3 % low instead of 0.9 %. Switched off
    (``NPY_DISABLE_CPU_FEATURES``), the fit must give the same bits: on a CPU without AVX-512 both runs are the same
    by construction, and that run shows nothing there.

    OpenBLAS picks its kernels by CPU; with its SSE3 ones (``OPENBLAS_CORETYPE=Prescott``) the same 6 s log fitted
    values ~1e-8 apart before the start, the observer's answer and CMA-ES's state were rounded (session 31), and the
    16 s slow ramps F2 +62 % instead of +145 %: the fit must give the same bits."""
    runs = []
    for disabled, core in (("", None), ("X86_V4 AVX512_ICL AVX512_SKX AVX512F", None), ("", "Prescott")):
        env = {**os.environ, "NPY_DISABLE_CPU_FEATURES": disabled, "OMP_NUM_THREADS": "1"}
        env.pop("OPENBLAS_CORETYPE", None)
        if core:
            env["OPENBLAS_CORETYPE"] = core
        done = subprocess.run([sys.executable, "-c", FIT_SCRIPT], env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        runs.append(done.stdout.strip().splitlines()[-1])
    assert runs[0] == runs[1] == runs[2], runs


def test_the_exact_elementary_functions_are_the_c_librarys_bit_for_bit():
    import math

    import numpy as np

    from pendulab import exact

    x = np.random.default_rng(3).normal(0.0, 3.0, 500)
    assert exact.exp(x).tolist() == [math.exp(v) for v in x]
    assert exact.sin(x).tolist() == [math.sin(v) for v in x] and exact.cos(x).tolist() == [math.cos(v) for v in x]
    positive = np.abs(x) + 1e-3
    assert exact.log(positive).tolist() == [math.log(v) for v in positive]
    assert exact.power(positive[:, None], np.arange(4.0)[None, :]).tolist() == [[math.pow(v, k) for k in range(4)] for v in positive]
    # numpy's edges, where math raises
    assert exact.exp(1000.0) == math.inf and exact.log(0.0) == -math.inf and math.isnan(exact.log(-1.0))
    assert exact.exp(709.5) == math.exp(709.5) < math.inf and math.isnan(exact.exp(math.nan))  # finite up to ~709.78
    assert exact.exp(np.zeros((2, 3))).shape == (2, 3)
    # a scalar gives a float (callers need no float() around them), an array of one element an array
    assert type(exact.log(2.0)) is float and type(exact.power(2.0, 0.5)) is float and type(exact.sin(np.float64(1.0))) is float
    assert isinstance(exact.exp(np.array([1.0])), np.ndarray) and isinstance(exact.power(np.array([2.0]), 2.0), np.ndarray)
