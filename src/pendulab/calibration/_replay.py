"""Compiled replay of logs through the plant under the true (switching) stick-slip law.

The fit's last stage and its check both replay a log's voltage through the plant of
:func:`pendulab.model.plant.plant_equations` with the law's switches as they are (no smoothing), at
the plant's own RK4 sub-step (:data:`pendulab.model.plant.MAX_SUBSTEP`), for one or several
parameter sets at once.

A replay may *restart* from a known state at chosen samples (:class:`pendulab.calibration._polish.Anchors`).
The step is unrolled over a fixed chunk of samples (:func:`_chunk_function`), mapped over parameter sets
and compiled to C once per machine (cached by :mod:`pendulab.native`).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
from functools import lru_cache
from typing import Sequence

import casadi as ca
import numpy as np

from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import MAX_SUBSTEP, step_function, substeps
from pendulab.native import shared_library

# OpenMP threads that finish their parameter sets sleep instead of spinning (set before libgomp starts):
# on a busy machine a spinning thread takes the core another process needs.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

#: IEEE arithmetic as written, whatever the compiler or CPU: no reassociation (which would let the
#: vectorizer reorder sums by the CPU's vector width) and no fused multiply-add. The same log then
#: replays to the same bits on any x86-64 machine and thread count (each parameter set is one thread's).
EXACT_MATH = ("-ffp-contract=off", "-fno-fast-math")
#: Samples per compiled call.
CHUNK = 500
#: Numbers of parameter sets compiled for (each a library built once per machine); others are padded.
SET_COUNTS = (1, 16, 32)


def _compile(functions: Sequence[ca.Function], name: str, optimize: str = "-O1", flags: Sequence[str] = ()) -> tuple[str | None, bool]:
    """Shared library holding ``functions`` (built once, cached by :func:`pendulab.native.shared_library`)
    and whether it was built just now; ``(None, False)`` without a working compiler."""
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for f in functions:
        gen.add(f)
    library = shared_library(gen.dump(), name, flags=(optimize, *flags), salt=ca.__version__, kind="fit", prebuilt=False)
    return (str(library.path), library.built) if library else (None, False)


@lru_cache(maxsize=None)
def _chunk_function(n_sub: int, n_sets: int, free: tuple[int, ...], fixed: tuple[float, ...], observer: int = 0) -> ca.Function:
    """One chunk of :data:`CHUNK` samples for ``n_sets`` parameter sets, compiled to C where it can be.

    The replay: ``F(s0[4 x m], V[1 x C], t[1 x C], restart[1 x C], s_restart[4 x C], theta[n_free x m], h)
    -> states[4 x C*m]``. The observer of ``observer`` outputs (1: the position; 2: and the angle; see
    :func:`observe`): ``F(s0[4 x m], V, t, y[ny x C], gain[4 x ny], theta, h) -> (s_end[4 x m],
    predicted[ny x C*m], corrected[4 x C*m])``.

    Only the parameters ``free`` (indices into :meth:`PlantParameters.names`) are inputs; the others are
    compiled in as the constants ``fixed``, so that a cart without a pendulum loses every pendulum term.
    """
    step = step_function(False, n_sub).expand()
    s, V, t, h = ca.SX.sym("s", 4), ca.SX.sym("V"), ca.SX.sym("t"), ca.SX.sym("h")
    theta = ca.SX.sym("theta", len(free))
    entries = [ca.SX(v) for v in fixed]
    for j, i in enumerate(free):
        entries[i] = theta[j]
    p = ca.vertcat(*entries)
    # MX, so that the chunk stays a loop over the one step in the generated C instead of being unrolled.
    s0, Vc, tc, thc, hc = ca.MX.sym("s0", 4), ca.MX.sym("V", 1, CHUNK), ca.MX.sym("t", 1, CHUNK), ca.MX.sym("theta", len(free)), ca.MX.sym("h")
    if observer:
        ny = observer
        y, gain = ca.SX.sym("y", ny), ca.SX.sym("gain", 4, ny)
        predicted = step(s, V, p, t, h)
        measured = predicted[[0, 2][:ny]]
        corrected = predicted + ca.mtimes(gain, y - measured)
        one = ca.Function("observe_step", [s, V, t, y, gain, theta, h], [corrected, measured, corrected])
        yc, gc = ca.MX.sym("y", ny, CHUNK), ca.MX.sym("gain", 4, ny)
        _, positions, states = one.mapaccum("observe_chunk", CHUNK, [0], [0])(s0, Vc, tc, yc, ca.repmat(gc, 1, CHUNK), ca.repmat(thc, 1, CHUNK), ca.repmat(hc, 1, CHUNK))
        chunk = ca.Function("observe_chunk1", [s0, Vc, tc, yc, gc, thc, hc], [states[:, -1], positions, states])
    else:
        r, sr = ca.SX.sym("r"), ca.SX.sym("sr", 4)
        one = ca.Function("replay_step", [s, V, t, r, sr, theta, h], [step(ca.if_else(r > 0.5, sr, s), V, p, t, h)])
        rc, src = ca.MX.sym("r", 1, CHUNK), ca.MX.sym("sr", 4, CHUNK)
        states = one.mapaccum("replay_chunk", CHUNK)(s0, Vc, tc, rc, src, ca.repmat(thc, 1, CHUNK), ca.repmat(hc, 1, CHUNK))
        chunk = ca.Function("replay_chunk1", [s0, Vc, tc, rc, src, thc, hc], [states])
    tag = hashlib.sha256(repr((n_sub, n_sets, free, fixed) + (("observer", observer, "states") if observer else ())).encode()).hexdigest()[:10]
    name = f"pendulab_{'observe' if observer else 'replay'}_{tag}"
    shared = [1, 2, 3, 4, 6]  # everything but the state and the parameters is the same for every set
    if n_sets > 1:
        # The parameter sets in parallel on the machine's cores (OpenMP in the generated C). CasADi's own
        # build has no OpenMP and warns about its evaluator, which is not used here: the warning is dropped.
        with contextlib.redirect_stderr(io.StringIO()):
            parallel = chunk.map(name, "openmp", n_sets, shared, [])
        library, _ = _compile([parallel], name, optimize="-O2", flags=("-fopenmp", *EXACT_MATH))
        if library:
            return ca.external(name, library)
    f = chunk.map(name, "serial", n_sets, shared, [])
    library, _ = _compile([f], name, optimize="-O2", flags=EXACT_MATH)
    return ca.external(name, library) if library else f


def _split(vector: np.ndarray, free: Sequence[str] | None) -> tuple[tuple[int, ...], tuple[float, ...]]:
    """``(free indices, fixed values)`` of a parameter vector: the key of its compiled replay (the same
    for :func:`prepare` and :func:`replay`, so that a prepared library is the one a replay loads)."""
    names = PlantParameters.names()
    free_idx = tuple(range(len(names))) if free is None else tuple(names.index(n) for n in free)
    return free_idx, tuple(0.0 if i in free_idx else float(v) for i, v in enumerate(vector))


def _inputs(vectors: np.ndarray, V: np.ndarray, t: np.ndarray, free: Sequence[str] | None, observer: int = 0) -> tuple:
    """What :func:`replay` and :func:`observe` share: the chunk function for ``vectors``, the voltage and times
    padded to whole chunks, the free parameters of every set (flat) and the sub-step."""
    n = len(V)
    period = float(t[1] - t[0]) if n > 1 else 1e-3
    n_sub = substeps(period, MAX_SUBSTEP)
    free_idx, fixed = _split(vectors[0], free)
    size = -(-n // CHUNK) * CHUNK
    Vp, tp = np.zeros(size), t[0] + period * np.arange(size)
    Vp[:n], tp[:n] = V, t
    P = np.ascontiguousarray(vectors[:, free_idx]).ravel()
    return _chunk_function(n_sub, len(vectors), free_idx, fixed, observer), Vp, tp, P, np.array([period / n_sub])


def prepare(params: PlantParameters, periods: Sequence[float], free: Sequence[str]) -> None:
    """Build (or load) the compiled replays for every width in :data:`SET_COUNTS` ahead of use."""
    free_idx, fixed = _split(np.asarray(params.as_vector(), dtype=float), free)
    for period in sorted(set(periods)):
        for m in SET_COUNTS:
            _chunk_function(substeps(period, MAX_SUBSTEP), m, free_idx, fixed)
            if m > 1:  # the fit's search runs on the observer (pendulab.calibration._observer)
                _chunk_function(substeps(period, MAX_SUBSTEP), m, free_idx, fixed, 2 if params.Mp > 0 else 1)


def replay(
    params: list[PlantParameters] | np.ndarray,
    V: np.ndarray,
    t: np.ndarray,
    x0: np.ndarray,
    restarts: dict[int, np.ndarray] | None = None,
    *,
    free: Sequence[str] | None = None,
) -> np.ndarray:
    """States after each logged sample for one or several parameter sets, ``(m, n, 4)``.

    Parameters
    ----------
    params : list of PlantParameters, or array (m, n_params)
        The parameter sets (full vectors in :meth:`PlantParameters.names` order).
    V : array (n,)
        Voltage held from ``t[k]`` to ``t[k] + period``.
    t : array (n,)
        Sample times at a fixed period.
    x0 : array (4,)
        State at ``t[0]``.
    restarts : dict, optional
        ``{k: state}``: the replay continues from ``state`` at ``t[k]`` (before step ``k``).
    free : sequence of str, optional
        The parameters that differ between the sets (default: all). The others take the first set's
        values and are compiled in as constants, which makes the replay faster.

    Examples
    --------
    >>> p = PlantParameters.preset("none")
    >>> t = np.arange(1000) * 1e-3
    >>> x = replay([p], np.full(1000, 3.0), t, np.zeros(4))[0, :, 0]
    >>> bool(x[-1] > 0.1)
    True
    """
    vectors = np.atleast_2d(
        np.array([q.as_vector() for q in params], dtype=float) if isinstance(params, list) and params and isinstance(params[0], PlantParameters) else np.asarray(params, dtype=float)
    )
    m, n = vectors.shape[0], len(V)
    if m not in SET_COUNTS:
        # A few compiled widths serve any number of sets: pad with copies of the first, or split.
        width = next((w for w in SET_COUNTS if w >= m), SET_COUNTS[-1])
        if m > width:
            return np.concatenate([replay(vectors[i : i + width], V, t, x0, restarts, free=free) for i in range(0, m, width)])
        padded = np.vstack([vectors, np.tile(vectors[:1], (width - m, 1))])
        return replay(padded, V, t, x0, restarts, free=free)[:m]
    f, Vp, tp, P, h = _inputs(vectors, V, t, free)
    size, n_chunks = len(Vp), len(Vp) // CHUNK
    rp = np.zeros(size)
    srp = np.zeros((4, size))
    for k, state in (restarts or {}).items():
        if 0 <= k < n:
            rp[k] = 1.0
            srp[:, k] = state
    # The compiled function reads and writes these arrays in place (a FunctionBuffer: no conversion to
    # and from CasADi's DM, which cost a fifth of a fit's time). CasADi's layout is column-major: a
    # (4 x m) matrix is a (m, 4) array here, and the result (4 x CHUNK*m) is (m, CHUNK, 4).
    state = np.tile(np.asarray(x0, dtype=float), m)
    V_in, t_in, r_in, sr_in = np.empty(CHUNK), np.empty(CHUNK), np.empty(CHUNK), np.empty(4 * CHUNK)
    result = np.empty(4 * CHUNK * m)
    buffer, evaluate = f.buffer()
    for i, a in enumerate((state, V_in, t_in, r_in, sr_in, P, h)):
        buffer.set_arg(i, a.data)
    buffer.set_res(0, result.data)
    out = np.empty((m, size, 4))
    states = result.reshape(m, CHUNK, 4)
    for c in range(n_chunks):
        sl = slice(c * CHUNK, (c + 1) * CHUNK)
        V_in[:], t_in[:], r_in[:] = Vp[sl], tp[sl], rp[sl]
        sr_in[:] = srp[:, sl].T.ravel()
        evaluate()
        out[:, sl, :] = states
        state[:] = states[:, -1, :].ravel()
    return out[:, :n, :]


def observer_compiled(params: PlantParameters, period: float, free: Sequence[str]) -> bool:
    """Whether :func:`observe` runs as compiled C here (else in CasADi's virtual machine, many times slower)."""
    free_idx, fixed = _split(np.asarray(params.as_vector(), dtype=float), free)
    outputs = 2 if params.Mp > 0 else 1
    return _chunk_function(substeps(period, MAX_SUBSTEP), SET_COUNTS[1], free_idx, fixed, outputs).class_name() == "External"


def observe(
    params: np.ndarray,
    V: np.ndarray,
    t: np.ndarray,
    y: np.ndarray,
    x0: np.ndarray,
    gain: np.ndarray,
    *,
    free: Sequence[str] | None = None,
    states: bool = False,
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Outputs predicted one sample ahead by an observer of the plant, ``(m, n)`` (``(m, n, 2)`` for two outputs).

    The replay of :func:`replay`, corrected after each sample towards the logged outputs ``y[k]`` (the
    position ``(n,)``, or the position and the angle ``(n, 2)``): ``state <- predicted + gain @ (y[k] -
    predicted outputs)`` with ``gain`` ``(4,)`` or ``(4, 2)``. A breakaway a millisecond early no longer
    shifts the rest of the log; each prediction shows only what the model gets wrong within about one
    observer time constant, and an upright pendulum, open-loop unstable, stays up. ``gain = 0`` is the
    replay itself. With ``states=True`` the corrected states ``(m, n, 4)`` too (the observer's estimate
    of the state after each sample). Arguments as :func:`replay`, with ``params`` an array ``(m, n_params)``.

    Examples
    --------
    >>> p = np.asarray(PlantParameters.preset("none").as_vector())[None]
    >>> t = np.arange(1000) * 1e-3
    >>> V = np.full(1000, 3.0)
    >>> x = replay(p, V, t, np.zeros(4))[0, :, 0]
    >>> bool(np.array_equal(observe(p, V, t, x, np.zeros(4), np.zeros(4))[0], x))
    True
    """
    vectors = np.atleast_2d(np.asarray(params, dtype=float))
    m, n = vectors.shape[0], len(V)
    Y = np.asarray(y, dtype=float).reshape(n, -1)
    ny = Y.shape[1]
    width = next((w for w in SET_COUNTS[1:] if w >= m), SET_COUNTS[-1])
    if m != width:
        parts = [vectors[i : i + width] for i in range(0, m, width)] if m > width else [np.vstack([vectors, np.tile(vectors[:1], (width - m, 1))])]
        done = [observe(q, V, t, y, x0, gain, free=free, states=True) for q in parts]
        predicted, corrected = np.concatenate([d[0] for d in done])[:m], np.concatenate([d[1] for d in done])[:m]
        return (predicted, corrected) if states else predicted
    f, Vp, tp, P, h = _inputs(vectors, V, t, free, ny)
    size, n_chunks = len(Vp), len(Vp) // CHUNK
    yp = np.zeros((size, ny))
    yp[:n] = Y
    # In place, as in replay(): column-major (4 x m) is (m, 4) here; the outputs (ny x CHUNK*m) are (m, CHUNK, ny).
    state = np.tile(np.asarray(x0, dtype=float), m)
    V_in, t_in, y_in = np.empty(CHUNK), np.empty(CHUNK), np.empty(ny * CHUNK)
    g = np.asarray(gain, dtype=float).reshape(4, ny).T.ravel().copy()  # column-major (4 x ny)
    end, predicted, corrected = np.empty(4 * m), np.empty(ny * CHUNK * m), np.empty(4 * CHUNK * m)
    buffer, evaluate = f.buffer()
    for i, a in enumerate((state, V_in, t_in, y_in, g, P, h)):
        buffer.set_arg(i, a.data)
    for i, a in enumerate((end, predicted, corrected)):
        buffer.set_res(i, a.data)
    out, estimates = np.empty((m, size, ny)), np.empty((m, size, 4))
    for c in range(n_chunks):
        sl = slice(c * CHUNK, (c + 1) * CHUNK)
        V_in[:], t_in[:], y_in[:] = Vp[sl], tp[sl], yp[sl].ravel()
        evaluate()
        out[:, sl] = predicted.reshape(m, CHUNK, ny)
        estimates[:, sl] = corrected.reshape(m, CHUNK, 4)
        state[:] = end
    out = out[:, :n, 0] if np.ndim(y) == 1 else out[:, :n]
    return (out, estimates[:, :n]) if states else out
