"""pendulab.exact: the fit's small linear algebra and smoothing, checked against numpy and scipy, and the same
bits whichever kernels OpenBLAS picks for the CPU (numpy's least squares and scipy's filter differ there in their last bits)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import savgol_filter

from pendulab import exact


@pytest.mark.parametrize("window", [5, 31, 101])
@pytest.mark.parametrize("deriv", [0, 1, 2])
def test_savgol_equals_scipys_interp_mode(window, deriv):
    y = np.cumsum(np.random.default_rng(1).normal(size=400))
    want = savgol_filter(y, window, 3, deriv=deriv, delta=1e-3)
    got = exact.savgol(y, window, 3, deriv=deriv, delta=1e-3)
    assert np.max(np.abs(got - want)) <= 1e-11 * np.max(np.abs(want))  # measured: 2e-13 at most


def test_solve_lstsq_and_dot_equal_numpys():
    rng = np.random.default_rng(2)
    A, b, B = rng.normal(size=(200, 3)), rng.normal(size=200), rng.normal(size=(200, 2))
    assert np.allclose(exact.lstsq(A, b), np.linalg.lstsq(A, b, rcond=None)[0], rtol=1e-12, atol=1e-14)
    assert np.allclose(exact.lstsq(A, B), np.linalg.lstsq(A, B, rcond=None)[0], rtol=1e-12, atol=1e-14)
    M, g = rng.normal(size=(4, 4)), rng.normal(size=4)
    assert np.allclose(exact.solve(M, g), np.linalg.solve(M, g), rtol=1e-12, atol=1e-14)
    assert np.allclose(exact.dot(M, B[:4]), M @ B[:4], rtol=1e-14, atol=1e-14)
    # A column that adds nothing gets 0 (numpy's minimum-norm answer too), the others their least squares.
    A[:, 1] = 0.0
    assert np.allclose(exact.lstsq(A, b), np.linalg.lstsq(A, b, rcond=None)[0], rtol=1e-12, atol=1e-14)
    with pytest.raises(np.linalg.LinAlgError):
        exact.solve(np.zeros((2, 2)), np.ones(2))


_BITS = """
import hashlib, numpy as np
from pendulab import exact
from pendulab.calibration._start import log_start
from pendulab.calibration.fit import _initial_states
from pendulab.calibration.synthetic import RIGS, synthetic_log
from pendulab.model.parameters import PlantParameters
rng = np.random.default_rng(0)
A = rng.normal(size=(60, 4, 4)); A = np.einsum('kij,klj->kil', A, A) + np.eye(4); g = rng.normal(size=(60, 4))
log = synthetic_log("triangle", RIGS["unseen"], duration=3.0)
start = log_start([log], PlantParameters.preset("none"))
parts = [np.array([exact.solve(a, b) for a, b in zip(A, g)]), exact.lstsq(A.reshape(-1, 4), g.ravel()[:240]),
         _initial_states(log, False), np.array([start.F1, start.Beq, start.force_gain])]
print(" ".join(hashlib.sha256(np.ascontiguousarray(p).tobytes()).hexdigest()[:12] for p in parts))
"""


def test_the_same_bits_on_any_blas_kernel():
    """OpenBLAS's generic SSE3 kernels (Prescott) against those it picks for this CPU: the fit's start is the same."""
    def bits(core: str | None) -> str:
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"} | ({"OPENBLAS_CORETYPE": core} if core else {})
        return subprocess.run([sys.executable, "-c", _BITS], env=env, capture_output=True, text=True, check=True).stdout.strip()

    assert bits(None) == bits("Prescott")


@pytest.mark.parametrize("n", [1, 2, 3, 7, 8])
def test_eigh_decomposes_like_lapack_with_fixed_signs(n):
    rng = np.random.default_rng(n)
    for _ in range(20):
        M = rng.normal(size=(n, n))
        A = M @ M.T + np.diag(rng.uniform(0.0, 1.0, n)) * 10.0 ** rng.uniform(-6, 0)
        values, vectors = exact.eigh(A)
        scale = float(np.max(np.abs(A)))
        assert np.allclose(values, np.linalg.eigvalsh(A), rtol=1e-11, atol=1e-12 * scale)
        assert np.all(np.diff(values) >= 0)
        assert np.allclose(vectors @ np.diag(values) @ vectors.T, A, atol=1e-12 * scale)
        assert np.allclose(vectors.T @ vectors, np.eye(n), atol=1e-12)
        largest = np.abs(vectors).argmax(axis=0)
        assert np.all(vectors[largest, np.arange(n)] > 0)  # each column's sign fixed: its largest component positive


def test_eigh_of_a_diagonal_and_a_degenerate_matrix():
    values, vectors = exact.eigh(np.diag([3.0, 1.0, 2.0]))
    assert values.tolist() == [1.0, 2.0, 3.0] and vectors.tolist() == [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    values, vectors = exact.eigh(np.eye(4))
    assert values.tolist() == [1.0] * 4 and vectors.tolist() == np.eye(4).tolist()


def test_significant_rounds_to_decimal_digits():
    assert exact.significant(2.8180000000000003, 7) == 2.818 and isinstance(exact.significant(1.0, 3), float)
    assert exact.significant(np.array([0.0049999999999999, -123456789.0, 0.0]), 4).tolist() == [0.005, -123500000.0, 0.0]
    assert exact.significant(1.23456749, 7) == 1.234567 and exact.significant(1.23456751, 7) == 1.234568
