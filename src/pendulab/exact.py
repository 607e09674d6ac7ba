"""Small dense linear algebra, the Savitzky-Golay filter, the elementary functions and rounding, with the same bits on any x86-64 machine.

numpy's ``linalg`` and ``@``, and scipy's ``savgol_filter`` (its coefficients come from a least-squares
solve), call OpenBLAS, which picks its kernels by CPU: a least-squares solve, a matrix product and a filter's
coefficients differ in their last bits between its AVX2 kernels and its SSE3 ones (``OPENBLAS_CORETYPE=Prescott``).
A 4x4 ``numpy.linalg.solve`` gave the same bits under both, but LAPACK calls BLAS too, so it goes through here. The fit's start
(smoothed states, the logs' own estimate), its restarts' states, its uncertainties and CMA-ES's eigen-decomposition
(:func:`eigh`) use these instead: every product is an elementwise ufunc (IEEE, no fused multiply-add) and every sum
runs in an order the code fixes. Meant for the few-column systems the fit solves, not for speed. What still comes through
OpenBLAS (scipy's least squares, pycma's products) is rounded (:func:`significant`) where a search goes on from it.

numpy's own ``exp``, ``log``, ``sin``, ``cos`` and ``power`` of float64 arrays take code of their own on a CPU with
AVX-512 (``numpy.show_runtime()``: ``X86_V4``, ``AVX512_SKX``) and the C library's elsewhere; the last bits differ, and
the fit's answer with them: a 16 s log of slow ramps fitted Beq 5.3 % low on an AVX-512 machine and 0.9 % low on AVX2
ones (``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL"`` showed it). :func:`exp`, :func:`log`, :func:`sin`, :func:`cos` and
:func:`power` call the C library's (Python's :mod:`math`) on every element, as numpy does without AVX-512.

Examples
--------
>>> A = np.array([[4.0, 1.0], [1.0, 3.0]])
>>> solve(A, np.array([1.0, 2.0])).round(6).tolist()
[0.090909, 0.636364]
>>> lstsq(np.array([[1.0, 0.0], [1.0, 1.0], [1.0, 2.0]]), np.array([1.0, 3.0, 5.0])).round(12).tolist()
[1.0, 2.0]
"""

from __future__ import annotations

import math

import numpy as np


def _exp(x: float) -> float:
    try:
        return math.exp(x)
    except OverflowError:  # numpy gives inf
        return math.inf


def _log(x: float) -> float:
    return math.log(x) if x > 0 else -math.inf if x == 0 else math.nan


_EXP, _LOG = np.vectorize(_exp, otypes=[float]), np.vectorize(_log, otypes=[float])
_SIN, _COS = np.vectorize(math.sin, otypes=[float]), np.vectorize(math.cos, otypes=[float])
_POWER = np.vectorize(math.pow, otypes=[float])


def _each(f: np.vectorize, *args: np.ndarray | float) -> np.ndarray | float:
    """``f`` on every element of ``args`` (broadcast): an array, or a float where every argument is a scalar."""
    out = f(*(np.asarray(a, dtype=float) for a in args))
    return float(out) if out.ndim == 0 else out


def exp(x: np.ndarray | float) -> np.ndarray | float:
    """``numpy.exp``, elementwise through the C library (see the module docstring); +inf where it overflows.
    A float for a scalar (here and in :func:`log`, :func:`sin`, :func:`cos`, :func:`power`), else an array."""
    return _each(_EXP, x)


def log(x: np.ndarray | float) -> np.ndarray | float:
    """``numpy.log``, elementwise through the C library; -inf at 0, nan below."""
    return _each(_LOG, x)


def sin(x: np.ndarray | float) -> np.ndarray | float:
    """``numpy.sin``, elementwise through the C library."""
    return _each(_SIN, x)


def cos(x: np.ndarray | float) -> np.ndarray | float:
    """``numpy.cos``, elementwise through the C library."""
    return _each(_COS, x)


def power(x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray | float:
    """``x ** y`` (broadcast), elementwise through the C library's ``pow``."""
    return _each(_POWER, x, y)


def dot(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A @ x`` (``A`` 2-D, ``x`` 1-D or 2-D), its sums taken term by term in order."""
    A, x = np.asarray(A, dtype=float), np.asarray(x, dtype=float)
    terms = A[:, :, None] * (x[None, :, None] if x.ndim == 1 else x[None])
    out = np.zeros(terms.shape[::2])
    for j in range(A.shape[1]):  # one column at a time: the same order on any machine
        out += terms[:, j]
    return out[:, 0] if x.ndim == 1 else out


def _back_substitute(R: np.ndarray, y: np.ndarray) -> np.ndarray:
    n = R.shape[1]
    x = np.zeros((n, *y.shape[1:]))
    for k in range(n - 1, -1, -1):
        rest = dot(R[k : k + 1, k + 1 : n], x[k + 1 :])[0] if k + 1 < n else 0.0
        x[k] = (y[k] - rest) / R[k, k] if R[k, k] != 0 else 0.0  # a column with no effect stays 0
    return x


def solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x`` with ``A x = b`` (Gaussian elimination with partial pivoting; ``b`` 1-D or 2-D)."""
    M, y = np.array(A, dtype=float), np.array(b, dtype=float)
    n = M.shape[0]
    for k in range(n):
        p = k + int(np.argmax(np.abs(M[k:, k])))
        if M[p, k] == 0:
            raise np.linalg.LinAlgError("singular matrix")
        M[[k, p]], y[[k, p]] = M[[p, k]], y[[p, k]]
        factors = M[k + 1 :, k] / M[k, k]
        M[k + 1 :, k:] -= factors[:, None] * M[k, k:][None, :]
        y[k + 1 :] -= factors.reshape(-1, *([1] * (y.ndim - 1))) * y[k]
    return _back_substitute(M, y)


def lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least-squares ``x`` minimizing ``|A x - b|`` (Householder QR); a column of zeros gets 0."""
    A, b = np.asarray(A, dtype=float), np.asarray(b, dtype=float)
    norms = np.sqrt(np.sum(A * A, axis=0))
    used = np.flatnonzero(norms > 1e-13 * max(float(np.max(norms)), 1e-300))
    R, y = A[:, used].copy(), b.copy()
    m, n = R.shape
    for k in range(min(n, m)):
        v = R[k:, k].copy()
        norm = math.sqrt(float(np.sum(v * v)))
        if norm == 0.0:
            continue
        v[0] += math.copysign(norm, v[0])
        vv = float(np.sum(v * v))
        column = v[:, None]
        R[k:, k:] -= column * (2.0 * np.sum(column * R[k:, k:], axis=0) / vv)[None, :]
        u = column if y.ndim == 2 else v
        y[k:] -= u * (2.0 * np.sum(u * y[k:], axis=0) / vv)
    x = np.zeros((A.shape[1], *b.shape[1:]))
    x[used] = _back_substitute(R[:n], y[:n])
    return x


def significant(x: np.ndarray | float, digits: int) -> np.ndarray | float:
    """``x`` rounded to ``digits`` significant decimal digits (Python's correctly rounded formatting).

    A result that came through LAPACK or an iterative solver may differ in its last bits, or further, between CPUs;
    where it starts a search that amplifies such differences, it is rounded first, so that only a value within that
    much of a rounding boundary can still tell two machines apart.

    Examples
    --------
    >>> significant(np.array([2.8180000000000003, 0.0049999999999999]), 7).tolist()
    [2.818, 0.005]
    """
    return _each(np.vectorize(lambda v: float(f"{v:.{digits - 1}e}"), otypes=[float]), x)


#: Jacobi sweeps of :func:`eigh` at most (a 7x7 matrix takes 6 to 8).
JACOBI_SWEEPS = 60


def eigh(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (ascending) and eigenvectors (columns) of the symmetric ``A``, by cyclic Jacobi rotations in Python floats.

    Unlike LAPACK's, each eigenvector's sign is fixed (its largest component, the first of equals, positive) and the
    bits do not depend on the CPU's kernels: CMA-ES samples along these vectors, and a column's sign flipped by
    another kernel sends it elsewhere. For small matrices (CMA-ES's covariance), not for speed.

    Examples
    --------
    >>> values, vectors = eigh(np.array([[2.0, 1.0], [1.0, 2.0]]))
    >>> values.round(12).tolist(), (vectors * 2 ** 0.5).round(12).tolist()
    ([1.0, 3.0], [[1.0, 1.0], [-1.0, 1.0]])
    """
    a = [[float(v) for v in row] for row in np.asarray(A, dtype=float)]
    n = len(a)
    v = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    for _ in range(JACOBI_SWEEPS):
        off = 0.0
        for p in range(n):
            for q in range(p + 1, n):
                off += a[p][q] * a[p][q]
        diagonal = 0.0
        for p in range(n):
            diagonal += a[p][p] * a[p][p]
        if off <= 1e-36 * diagonal or off == 0.0:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                if a[p][q] == 0.0:
                    continue
                tau = (a[q][q] - a[p][p]) / (2.0 * a[p][q])  # the rotation that zeroes a[p][q] (Golub & Van Loan, sym.schur2)
                t = 1.0 / (tau + math.sqrt(1.0 + tau * tau)) if tau >= 0 else -1.0 / (-tau + math.sqrt(1.0 + tau * tau))
                c = 1.0 / math.sqrt(1.0 + t * t)
                s = t * c
                for k in range(n):  # columns p and q: A J
                    akp, akq = a[k][p], a[k][q]
                    a[k][p], a[k][q] = c * akp - s * akq, s * akp + c * akq
                for k in range(n):  # rows p and q: J^T (A J)
                    apk, aqk = a[p][k], a[q][k]
                    a[p][k], a[q][k] = c * apk - s * aqk, s * apk + c * aqk
                for k in range(n):
                    vkp, vkq = v[k][p], v[k][q]
                    v[k][p], v[k][q] = c * vkp - s * vkq, s * vkp + c * vkq
    order = sorted(range(n), key=lambda j: (a[j][j], j))
    values = np.array([a[j][j] for j in order])
    vectors = np.array([[v[i][j] for j in order] for i in range(n)])
    for j in range(n):
        largest = max(range(n), key=lambda i: (abs(vectors[i, j]), -i))
        if vectors[largest, j] < 0:
            vectors[:, j] = -vectors[:, j]
    return values, vectors


def savgol(y: np.ndarray, window: int, order: int = 3, deriv: int = 0, delta: float = 1.0) -> np.ndarray:
    """Savitzky-Golay filter (``window`` odd), as ``scipy.signal.savgol_filter(..., mode="interp")``: the polynomial
    fitted to each window, its ``deriv``-th derivative at the window's centre; the first and last half windows
    from the polynomial of the first and last window."""
    y = np.asarray(y, dtype=float)
    half = window // 2
    k = np.arange(window) - half
    s = k / max(half, 1)  # scaled positions: a well-conditioned fit
    V = power(s[:, None], np.arange(order + 1)[None, :])
    gram = np.sum(V[:, :, None] * V[:, None, :], axis=0)
    G = solve(gram, V.T)  # (order + 1, window): coefficients of the polynomial from the window's samples
    powers = np.arange(order + 1)
    falling = np.array([math.perm(j, deriv) for j in powers], dtype=float)
    E = falling[None, :] * np.where(powers[None, :] >= deriv, power(s[:, None], np.maximum(powers - deriv, 0)[None, :]), 0.0)
    C = dot(E, G) / (max(half, 1) * delta) ** deriv  # row p: the derivative at window position p
    n = len(y)
    out = np.zeros(n)
    centre = C[half]
    for j in range(window):  # interior: the centre row slid along the samples, one term at a time
        out[half : n - half] += centre[j] * y[j : n - window + 1 + j]
    out[:half] = dot(C[:half], y[:window])
    out[n - half :] = dot(C[half + 1 :], y[n - window :])
    return out
