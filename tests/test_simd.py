"""pendulab.simd: every SX operation it translates gives CasADi's virtual machine's bits, in every lane width.

The fit's replay (``tests/test_fit_reproducible.py``) uses the operations a plant step has; here each one
the translator knows, on values a replay can meet and ones it should not (signed zeros, infinities, NaN).
"""

from __future__ import annotations

import ctypes
import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pendulab import simd
from pendulab.native import find_compiler, shared_library

x, y = ca.SX.sym("x"), ca.SX.sym("y")
EXPRESSIONS = [
    x + y, x - y, x * y, x / y, -x, 2 * x, x**2, x < y, x <= y, x == y, x != y,
    ca.logic_and(x, y), ca.logic_or(x, y), ca.logic_not(x), ca.if_else(x < y, x, y * 3.0), ca.if_else(x, y, 0.5),
    ca.fabs(x), ca.fmin(x, y), ca.fmax(x, y), ca.sign(x), ca.sin(x), ca.cos(x), ca.sqrt(x), ca.floor(x), ca.exp(x),
    ca.tanh(x), ca.atan2(x, y), x ** 3.5, x + 0.1,
    # truths passed on between operations as lane masks, and a truth taken as a number
    ca.logic_and(x < y, ca.logic_not(x == 0.5)), ca.logic_or(ca.logic_not(x <= y), y), ca.if_else(ca.logic_and(x, y < 1.0), x, -y),
    (x < y) * 3.0 + x, ca.logic_not(ca.logic_not(x)) + 0.0,
]
FUNCTION = ca.Function("f", [x, y], [ca.vertcat(*EXPRESSIONS)])
DRIVER = r"""
void pendulab_run(int n, const double *x, const double *y, double *out) {
    for (int g = 0; g < n / LANES; ++g) {
        vd a, b, r[NOUT];
        for (int l = 0; l < LANES; ++l) { a[l] = x[g * LANES + l]; b[l] = y[g * LANES + l]; }
STEP
        for (int l = 0; l < LANES; ++l)
            for (int i = 0; i < NOUT; ++i) out[(size_t)(g * LANES + l) * NOUT + i] = r[i][l];
    }
}
"""
SOURCE = simd.PRELUDE + f"#define NOUT {len(EXPRESSIONS)}\n" + DRIVER.replace(
    "STEP", simd.statements(FUNCTION, [lambda j, g: "a", lambda j, g: "b"], [lambda j, e, g: f"r[{j}] = {e};"])
)
pytestmark = pytest.mark.skipif(find_compiler() is None, reason="needs a C compiler")


def run_lanes(lanes: int, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    library = shared_library(SOURCE, f"pendulab_simd_test_{lanes}", flags=("-O2", f"-DLANES={lanes}", "-ffp-contract=off"), kind="test", prebuilt=False)
    run = ctypes.CDLL(str(library.path)).pendulab_run
    out = np.empty((len(xs), len(EXPRESSIONS)))
    pointer = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
    run(ctypes.c_int(len(xs)), pointer(np.ascontiguousarray(xs)), pointer(np.ascontiguousarray(ys)), pointer(out))
    return out


def in_vm(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    return np.asarray(FUNCTION.map(len(xs))(xs[None], ys[None])).T


def same_bits(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Equal as IEEE bit patterns, any NaN equal to any NaN (CasADi's NaN payloads are not the C library's)."""
    return (a.view(np.int64) == b.view(np.int64)) | (np.isnan(a) & np.isnan(b))


SPECIAL = [0.0, -0.0, 1.0, -1.0, 0.5, -2.5, 1e-310, 3.0, math.inf, -math.inf, math.nan, 1e300, -7.25]


@pytest.mark.parametrize("lanes", [1, 2, 4, 8])
def test_every_operation_on_special_values_matches_the_virtual_machine(lanes):
    xs, ys = (np.array(v, dtype=float).ravel() for v in np.meshgrid(SPECIAL, SPECIAL))
    pad = -len(xs) % 8
    xs, ys = np.r_[xs, np.ones(pad)], np.r_[ys, np.ones(pad)]
    got, want = run_lanes(lanes, xs, ys), in_vm(xs, ys)
    wrong = ~same_bits(got, want)
    assert not wrong.any(), [(str(EXPRESSIONS[j]), xs[i], ys[i], got[i, j], want[i, j]) for i, j in zip(*np.nonzero(wrong))][:5]


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e3, 1e3)), min_size=8, max_size=8))
def test_random_values_give_the_virtual_machines_bits(pairs):
    xs, ys = (np.array(v, dtype=float) for v in zip(*pairs))
    assert same_bits(run_lanes(4, xs, ys), in_vm(xs, ys)).all()


def test_an_operation_without_a_lane_form_is_named():
    f = ca.Function("g", [x], [ca.erf(x)])
    with pytest.raises(NotImplementedError, match="ERF"):
        simd.statements(f, [lambda j, g: "a"], [lambda j, e, g: ""])
