"""Discrete realization of the controller: exact Tustin/ZOH, sound factor-by-factor structure, FMU parameters."""

from __future__ import annotations

import control
import numpy as np
import pytest
import scipy.signal

from pendulab.control.controller import Controller, Factor, demo_controller
from pendulab.control.realization import MAX_ORDER, DiscreteLTI, continuous_realization, discretize, sections
from pendulab.errors import ControllerError

H = 1e-3


def random_roots(rng: np.random.Generator, count: int, unstable: bool) -> list:
    """``count`` roots (real ones and conjugate pairs), magnitudes 0.5..200, none at 0."""
    roots: list = []
    while len(roots) < count:
        magnitude = float(np.exp(rng.uniform(np.log(0.5), np.log(200.0))))
        sign = 1.0 if (unstable and rng.random() < 0.3) else -1.0
        if count - len(roots) >= 2 and rng.random() < 0.4:
            angle = rng.uniform(0.1, 1.4)
            root = complex(sign * magnitude * np.cos(angle), magnitude * np.sin(angle))
            roots += [root, root.conjugate()]
        else:
            roots.append(sign * magnitude)
    return roots


def random_controller(rng: np.random.Generator, n_factors: int, unstable: bool = True) -> Controller:
    factors = []
    for i in range(n_factors):
        n_poles = int(rng.integers(1, 3))
        n_zeros = int(rng.integers(0, n_poles + 1))
        gain = float(rng.choice([-1, 1]) * np.exp(rng.uniform(-2, 4)))
        factors.append(Factor(random_roots(rng, n_zeros, unstable), random_roots(rng, n_poles, unstable), gain))
    return Controller(factors)


def reference_response(controller: Controller, h: float, method: str, u: np.ndarray) -> np.ndarray:
    """python-control's own discretization (``control.c2d``) of the whole controller, simulated by python-control.

    The transfer function goes through a state space first: ``c2d`` of a high-order *transfer
    function* at 1 ms returns polynomials whose roots (all near z = 1) are lost to round-off, the very
    problem the sectioned realization avoids (see ``test_tustin_frequency_response_is_exact``).
    """
    g = control.c2d(control.ss(controller.transfer_function()), h, method=method)
    return control.forced_response(g, U=u).outputs


def exact_response(controller: Controller, s: complex) -> complex:
    """G(s) straight from the zeros, poles and gain (no polynomial is formed)."""
    zeros, poles, gain = controller.zpk()
    return complex(gain * np.prod(s - zeros) / np.prod(s - poles))


@pytest.mark.filterwarnings("ignore::scipy.linalg.LinAlgWarning")  # inside the reference's companion form
@pytest.mark.parametrize("method", ["tustin", "zoh"])
@pytest.mark.parametrize("seed", range(12))
def test_matches_python_control_c2d(seed, method):
    rng = np.random.default_rng(seed)
    n_factors = 6 if seed < 4 else int(rng.integers(1, 6))
    controller = random_controller(rng, n_factors, unstable=seed % 2 == 1)
    lti = discretize(controller, h=H, method=method)
    assert lti.order == controller.order and lti.method == method and lti.h == H
    u = rng.normal(size=400)
    y = lti.step_response(u)
    ref = reference_response(controller, H, method, u)
    assert np.max(np.abs(y - ref)) <= 1e-7 * np.max(np.abs(ref))


@pytest.mark.parametrize("method", ["tustin", "zoh"])
def test_demo_matches_python_control(method):
    c = demo_controller()
    u = np.ones(2000)
    y = discretize(c, method=method).step_response(u)
    ref = reference_response(c, H, method, u)
    assert np.max(np.abs(y - ref)) <= 1e-10 * np.max(np.abs(ref))
    # the same from a TransferFunction input
    y_tf = discretize(c.transfer_function(), method=method).step_response(u)
    assert np.max(np.abs(y_tf - ref)) <= 1e-8 * np.max(np.abs(ref))


def test_zoh_is_exact_at_the_samples():
    """ZOH: a step held between samples gives the continuous step response at the sample times."""
    c = Controller([Factor([-2.0], [-5.0, complex(-3, 10), complex(-3, -10)], 40.0), Factor([-30.0], [-8.0])])
    n = 600
    y = discretize(c, h=H, method="zoh").step_response(np.ones(n))
    t = np.arange(n) * H
    _, y_cont = scipy.signal.step(scipy.signal.lti(*continuous_realization(c)), T=t)
    assert np.max(np.abs(y - y_cont)) <= 1e-9 * np.max(np.abs(y_cont))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_tustin_frequency_response_is_exact(seed):
    """Tustin: H(e^{jwh}) = G(j (2/h) tan(wh/2)) at every frequency, for the demo and 6-factor controllers."""
    c = demo_controller() if seed == 0 else random_controller(np.random.default_rng(seed), 6, unstable=seed % 2 == 1)
    lti = discretize(c, h=H)
    for w in (0.3, 5.0, 80.0, 900.0, 2500.0):
        z = np.exp(1j * w * H)
        h_z = (lti.C @ np.linalg.solve(z * np.eye(lti.order) - lti.A, lti.B) + lti.D)[0, 0]
        assert np.isclose(h_z, exact_response(c, 1j * 2 / H * np.tan(w * H / 2)), rtol=1e-10)


def test_continuous_realization_is_block_triangular_and_exact():
    rng = np.random.default_rng(99)
    c = random_controller(rng, 6)
    A, B, C, D = continuous_realization(c)
    assert np.all(np.triu(A, 2) == 0)  # first/second-order sections in series
    for s in (0.7j, 3 + 4j, 150j):
        value = (C @ np.linalg.solve(s * np.eye(len(A)) - A, B) + D)[0, 0]
        assert np.isclose(value, exact_response(c, s), rtol=1e-11)


@pytest.mark.parametrize("method, mapping", [("tustin", lambda p: (1 + p * H / 2) / (1 - p * H / 2)), ("zoh", lambda p: np.exp(p * H))])
def test_high_order_poles_are_kept_exactly(method, mapping):
    """16 poles from 1 to 3000 rad/s: a single companion form would scramble them; sections do not."""
    poles = list(-np.geomspace(1.0, 3000.0, 12)) + [complex(-20, 300), complex(-20, -300), complex(5, 40), complex(5, -40)]
    zeros = list(-np.geomspace(2.0, 2000.0, 10))
    c = Controller([Factor(zeros[:5], poles[:8], 1e3), Factor(zeros[5:], poles[8:], 1.0)])
    lti = discretize(c, method=method)
    assert lti.order == MAX_ORDER
    assert np.all(np.abs(np.triu(lti.A, 2)) <= 1e-12 * np.max(np.abs(lti.A)))
    expected = np.sort_complex(np.array([mapping(complex(p)) for p in poles]))
    got = np.sort_complex(lti.poles())
    assert np.max(np.abs(got - expected)) < 1e-10


def test_sections_keep_pairs_and_are_proper():
    zeros = [complex(-1, 2), complex(-1, -2), -3.0, complex(-5, 1), complex(-5, -1)]
    poles = [-10.0, -20.0, -30.0, -40.0, -50.0, -60.0]
    secs = sections(zeros, poles)
    assert sum(len(p) for _, p in secs) == 6 and sum(len(z) for z, _ in secs) == 5
    for z, p in secs:
        assert 1 <= len(p) <= 2 and len(z) <= len(p)
        assert np.allclose(np.poly(z).imag if z else 0, 0) and np.allclose(np.poly(p).imag, 0)


def test_pure_gain_controller():
    lti = discretize(Controller.from_zpk([], [], -3.5))
    assert lti.order == 0 and lti.to_parameters() == {"n": 0, "D": -3.5}
    assert np.allclose(lti.step_response([1.0, 2.0]), [-3.5, -7.0])


def test_to_parameters_layout():
    lti = discretize(demo_controller())
    p = lti.to_parameters()
    n = lti.order
    assert p["n"] == n == 3 and isinstance(p["n"], int)
    assert len(p) == n * n + 2 * n + 2
    assert p["A[2,1]"] == lti.A[1, 0] and p["A[1,2]"] == lti.A[0, 1]
    assert p["B[3]"] == lti.B[2, 0] and p["C[1]"] == lti.C[0, 0] and p["D"] == lti.D[0, 0]
    assert all(isinstance(v, float) for k, v in p.items() if k != "n")


def test_step_response_from_a_state():
    lti = discretize(demo_controller())
    u = np.zeros(3)
    x0 = np.array([1.0, 0.0, 0.0])
    y = lti.step_response(u, x0=x0)
    assert np.isclose(y[0], lti.C[0] @ x0) and np.isclose(y[1], lti.C[0] @ lti.A @ x0)
    assert isinstance(lti, DiscreteLTI) and len(lti.poles()) == 3


def test_discretize_errors():
    c = demo_controller()
    for kwargs, fragment in [
        ({"h": 0.0}, "must be a positive"),
        ({"h": float("nan")}, "must be a positive"),
        ({"h": "fast"}, "not a number"),
        ({"method": "euler"}, "unknown discretization method"),
    ]:
        with pytest.raises(ControllerError, match=fragment):
            discretize(c, **kwargs)
    too_big = Controller([Factor([], -np.arange(1.0, 18.0))])
    with pytest.raises(ControllerError, match="order 17"):
        discretize(too_big)
    with pytest.raises(ControllerError, match="2/h"):
        discretize(Controller.from_zpk([], [2000.0], 1.0), h=1e-3)
    assert discretize(Controller.from_zpk([], [2000.0], 1.0), h=1e-3, method="zoh").order == 1
    with pytest.raises(ControllerError, match="exactly at s = 0"):
        discretize(control.tf([1.0], [1.0, 0.0]))
    with pytest.raises(ControllerError, match="cannot discretize"):
        discretize([1, 2, 3])
    assert discretize(c, method="bilinear").method == "tustin"


REALIZATION_SCRIPT = """
import hashlib
import numpy as np
from pendulab.control.controller import demo_controller
from pendulab.control.realization import continuous_realization
for kind in ("long", "short"):
    matrices = continuous_realization(demo_controller(kind))
    print(kind, hashlib.sha256(b"".join(np.ascontiguousarray(m, dtype=float).tobytes() for m in matrices)).hexdigest())
"""


def test_the_realization_has_the_same_bits_with_numpys_avx512_code_switched_off():
    """numpy's log and exp of a float take code of their own on an AVX-512 CPU: the sections' gains (log, exp) and so
    the controller's coefficients differed in their last bits from an AVX2 machine's, and a closed loop's run with them
    from its first disturbance on (the fit's synthetic closed-loop logs: a corpus case replayed at 3.35 steps here,
    1.19 with numpy's AVX-512 code off). They go through the C library (pendulab.exact): the same bits either way. On a
    CPU without AVX-512 both runs are the same by construction."""
    import os
    import subprocess
    import sys

    runs = []
    for disabled in ("", "X86_V4 AVX512_ICL AVX512_SKX AVX512F"):
        done = subprocess.run([sys.executable, "-c", REALIZATION_SCRIPT], env={**os.environ, "NPY_DISABLE_CPU_FEATURES": disabled},
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        runs.append(done.stdout)
    assert runs[0] == runs[1] and runs[0].count("\n") == 2, runs
