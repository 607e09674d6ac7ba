"""Compiled replay of logs through the plant under the true (switching) stick-slip law.

The fit's last stage and its check replay a log's voltage through the plant of :func:`pendulab.model.plant.plant_equations` with the law's switches as
they are (no smoothing), at the plant's own RK4 sub-step (:data:`pendulab.model.plant.MAX_SUBSTEP`), for several parameter sets at once.

A replay may *restart* from a known state at chosen samples (:class:`pendulab.calibration._polish.Anchors`). One sample's step is a CasADi SX function
(:func:`_step`), compiled once per machine to C that runs several parameter sets in the lanes of the CPU's vectors (:mod:`pendulab.simd`), the groups
of sets on the machine's cores (OpenMP); without a compiler CasADi's virtual machine evaluates it, set by set.
"""

from __future__ import annotations

import ctypes
import os
import sys
from functools import lru_cache
from typing import Sequence

import casadi as ca
import numpy as np

from pendulab import simd
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import MAX_SUBSTEP, step_function, substeps
from pendulab.native import shared_library

# OpenMP threads that finish their sets sleep, not spin (set before libgomp starts): on a busy machine a spinning thread takes a core others need.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

#: IEEE arithmetic as written, whatever the compiler or CPU: no reassociation and no fused multiply-add. Each parameter set is one vector lane's from
#: start to end, so the same log replays to the same bits on any x86-64 machine, vector width and thread count: those of CasADi's virtual machine.
EXACT_MATH = ("-ffp-contract=off", "-fno-fast-math")

#: Groups of lanes interleaved in one thread (:func:`pendulab.simd.statements`): each thread takes WAYS x LANES parameter sets at a time through the
#: whole log (a short last group repeats the last set).
WAYS = 4

#: What both drivers share: the lanes of group ``g`` start at ``x0``, each with its set's free parameters.
_GROUP = r"""
static inline void start_group(int g, int m, const double *x0, const double *P, vd (*s)[4], vd (*th)[NTH]) {
    const int size = WAYS * LANES;
    for (int q = 0; q < size; ++q) {
        const size_t set = g * size + q < m ? g * size + q : m - 1;
        for (int i = 0; i < 4; ++i) s[q / LANES][i][q % LANES] = x0[i];
        for (int i = 0; i < NFREE; ++i) th[q / LANES][i][q % LANES] = P[set * NFREE + i];
    }
}
"""
#: Around one sample's step (``STEP``); the replay's step restarts from ``sr`` where ``r`` is set.
_REPLAY = r"""
static inline void step(vd (*s)[4], double V, double t, double r, const double *sr, vd (*th)[NTH], double h, vd (*ns)[4]) {
STEP
}
void pendulab_run(int m, int n, const double *x0, const double *V, const double *t, const double *r, const double *sr,
                  const double *P, double h, double *states) {
    const int size = WAYS * LANES, groups = (m + size - 1) / size;
    #pragma omp parallel for schedule(static)
    for (int g = 0; g < groups; ++g) {
        vd s[WAYS][4], ns[WAYS][4], th[WAYS][NTH];
        start_group(g, m, x0, P, s, th);
        for (int k = 0; k < n; ++k) {
            for (int j = 0; j < NSUB; ++j) {  /* the sample's sub-steps, one at a time (see _step) */
                step(s, V[k], j ? t[k] + j * h : t[k], j ? 0.0 : r[k], sr + 4 * (size_t)k, th, h, ns);
                for (int w = 0; w < WAYS; ++w)
                    for (int i = 0; i < 4; ++i) s[w][i] = ns[w][i];
            }
            for (int q = 0; q < size && g * size + q < m; ++q)
                for (int i = 0; i < 4; ++i) states[((size_t)(g * size + q) * n + k) * 4 + i] = ns[q / LANES][i][q % LANES];
        }
    }
}
"""
#: The observer's: the step predicts the outputs (``pm``) and corrects the state towards ``y`` (``ns``).
_OBSERVE = r"""
static inline void step(vd (*s)[4], double V, double t, const double *y, const double *gain, double c, vd (*th)[NTH], double h, vd (*ns)[4], vd (*pm)[NY]) {
STEP
}
void pendulab_run(int m, int n, const double *x0, const double *V, const double *t, const double *y, const double *gain,
                  const double *P, double h, double *predicted, double *corrected) {
    const int size = WAYS * LANES, groups = (m + size - 1) / size;
    #pragma omp parallel for schedule(static)
    for (int g = 0; g < groups; ++g) {
        vd s[WAYS][4], ns[WAYS][4], pm[WAYS][NY], th[WAYS][NTH];
        start_group(g, m, x0, P, s, th);
        for (int k = 0; k < n; ++k) {
            for (int j = 0; j < NSUB; ++j) {  /* corrected after the last sub-step only (c = 1) */
                step(s, V[k], j ? t[k] + j * h : t[k], y + NY * (size_t)k, gain, j == NSUB - 1, th, h, ns, pm);
                for (int w = 0; w < WAYS; ++w)
                    for (int i = 0; i < 4; ++i) s[w][i] = ns[w][i];
            }
            for (int q = 0; q < size && g * size + q < m; ++q) {
                const size_t row = (size_t)(g * size + q) * n + k;
                for (int i = 0; i < NY; ++i) predicted[row * NY + i] = pm[q / LANES][i][q % LANES];
                for (int i = 0; i < 4; ++i) corrected[row * 4 + i] = ns[q / LANES][i][q % LANES];
            }
        }
    }
}
"""


@lru_cache(maxsize=None)
def _step(free: tuple[int, ...], fixed: tuple[float, ...], observer: int = 0) -> ca.Function:
    """One RK4 sub-step of a replay sample (the drivers run a sample's ``n_sub`` of them), or the observer's with ``observer`` outputs (1: x; 2: x, alpha).

    The replay: ``(s[4], V, t, r, sr[4], theta[n_free], h) -> s_next[4]`` (restarted from ``sr`` where ``r > 0.5``, its positions only, the speeds
    carried on, where ``r > 1.5``). The observer: ``(s[4], V, t, y[ny], gain[4 x ny], c, theta, h) -> (corrected[4], predicted[ny], corrected[4])``,
    the correction times ``c`` (1 after a sample's last sub-step, else 0). Only the parameters ``free`` (indices into :meth:`PlantParameters.names`) are
    inputs; the others are the constants ``fixed``, so that a cart without a pendulum loses every pendulum term.
    """
    # One sub-step, looped by the C driver: a sample's 10 unrolled compiled 5 times slower (3-5 s of gcc per replay), ran 1-11 % slower, same bits.
    step = step_function(False, 1).expand()
    s, V, t, h = ca.SX.sym("s", 4), ca.SX.sym("V"), ca.SX.sym("t"), ca.SX.sym("h")
    theta = ca.SX.sym("theta", len(free))
    p = ca.vertcat(*(theta[free.index(i)] if i in free else ca.SX(v) for i, v in enumerate(fixed)))  # free: its symbol
    if observer:
        y, gain, c = ca.SX.sym("y", observer), ca.SX.sym("gain", 4, observer), ca.SX.sym("c")
        predicted = step(s, V, p, t, h)
        measured = predicted[[0, 2][:observer]]
        corrected = predicted + c * ca.mtimes(gain, y - measured)
        return _by_reciprocals(ca.Function("observe_step", [s, V, t, y, gain, c, theta, h], [corrected, measured, corrected]))
    r, sr = ca.SX.sym("r"), ca.SX.sym("sr", 4)
    restarted = ca.if_else(r > 1.5, ca.vertcat(sr[0], s[1], sr[2], s[3]), ca.if_else(r > 0.5, sr, s))  # r 2: the positions only
    return _by_reciprocals(ca.Function("replay_step", [s, V, t, r, sr, theta, h], [step(restarted, V, p, t, h)]))


def _by_reciprocals(f: ca.Function) -> ca.Function:
    """``f`` with each division by a constant (the fixed parameters, compiled in: a cart's mass, the motor's constants) a multiplication by the
    constant's reciprocal: a division costs the CPU several multiplications' time, and the cart's replay ran 11 % faster. Its results differ from
    ``f``'s in their last bits only; the compiled replay and CasADi's virtual machine both run this one, so they still agree to the bit."""
    inputs, work = f.sx_in(), {}
    outputs = [ca.SX.zeros(f.sparsity_out(i)) for i in range(f.n_out())]
    for k in range(f.n_instructions()):
        op, a, o = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            work[o[0]] = inputs[a[0]].nz[a[1]]
        elif op == ca.OP_OUTPUT:
            outputs[o[0]].nz[o[1]] = work[a[0]]
        elif op == ca.OP_CONST:
            work[o[0]] = ca.SX(f.instruction_constant(k))
        elif op == ca.OP_DIV and work[a[1]].is_constant():
            work[o[0]] = work[a[0]] * ca.SX(1.0 / float(work[a[1]]))
        else:
            work[o[0]] = ca.SX.binary(op, work[a[0]], work[a[1]]) if len(a) == 2 else ca.SX.unary(op, work[a[0]])
    return ca.Function(f.name(), inputs, outputs, f.name_in(), f.name_out())


@lru_cache(maxsize=None)
def _sample(n_sub: int, free: tuple[int, ...], fixed: tuple[float, ...], observer: int = 0) -> ca.Function:
    """One whole sample for CasADi's VM: :func:`_step`'s sub-steps as the compiled drivers run them (same operations, same bits), without ``c``."""
    one = _step(free, fixed, observer)
    ins = [ca.SX.sym(one.name_in(i), one.sparsity_in(i)) for i in range(one.n_in())]
    s, V, t, h = ins[0], ins[1], ins[2], ins[-1]
    for j in range(n_sub):
        tj = t + j * h if j else t
        out = one.call([s, V, tj, *ins[3:5], float(j == n_sub - 1), *ins[6:]] if observer else [s, V, tj, ins[3] if j == 0 else 0.0, *ins[4:]])
        s = out[0]
    return ca.Function(one.name(), [x for i, x in enumerate(ins) if not (observer and i == 5)], out)


def _source(n_sub: int, free: tuple[int, ...], fixed: tuple[float, ...], observer: int = 0, ways: int = WAYS) -> str:
    """The C of :data:`_REPLAY` (or :data:`_OBSERVE`) around :func:`_step`, over :mod:`pendulab.simd`'s lanes."""
    one = _step(free, fixed, observer)
    # Each input's nonzero j for group g: the group's own (its state, its sets' parameters) or one for every set, bc().
    given = ["bc(y[{j}])", "bc(gain[{j}])", "bc(c)"] if observer else ["bc(r)", "bc(sr[{j}])"]
    inputs = [lambda j, g, text=text: text.format(j=j, g=g) for text in ("s[{g}][{j}]", "bc(V)", "bc(t)", *given, "th[{g}][{j}]", "bc(h)")]
    # The next state, and the observer's predicted outputs (its third output, the next state again, is not stored).
    outputs = [lambda j, e, g: f"ns[{g}][{j}] = {e};", lambda j, e, g: f"pm[{g}][{j}] = {e};", lambda j, e, g: ""][: one.n_out()]
    defines = (f"#define WAYS {ways}\n#define NFREE {len(free)}\n#define NTH {max(len(free), 1)}\n#define NY {max(observer, 1)}\n"
               f"#define NSUB {n_sub}\n")
    return simd.PRELUDE + defines + _GROUP + (_OBSERVE if observer else _REPLAY).replace("STEP", simd.statements(one, inputs, outputs, ways))


def _load(source: str, name: str, flags: Sequence[str]):
    """``pendulab_run`` of ``source`` compiled with ``flags`` and OpenMP, else without (the groups of sets one after another: Apple's clang has no
    OpenMP), cached per machine; None if no compiler builds it or it does not load here."""
    for threads in (("-fopenmp",), ()):
        library = shared_library(source, name, flags=(*flags, *threads, *EXACT_MATH), salt=simd.salt(), kind="fit", prebuilt=False)
        if library is None:
            continue
        try:
            # On Windows the OpenMP runtime (MinGW's libgomp) is found on PATH only with the classic search.
            run = ctypes.CDLL(str(library.path), **({"winmode": 0} if sys.platform == "win32" else {})).pendulab_run
        except OSError:
            continue
        run.restype = None
        return run
    return None


@lru_cache(maxsize=None)
def _compiled(n_sub: int, free: tuple[int, ...], fixed: tuple[float, ...], observer: int = 0, single: bool = False):
    """:func:`_source` built once per machine (:func:`pendulab.native.shared_library`): in :func:`pendulab.simd.lanes` lanes, :data:`WAYS` groups of
    them (``single``: one lane, for a lone set), for the machine's own vector width (else the baseline's); None without a compiler."""
    # Named by its C alone (shared_library hashes it with the flags): keys that give the same C share one build.
    name = f"pendulab_{'observe' if observer else 'replay'}"
    source = _source(n_sub, free, fixed, observer, 1 if single else WAYS)
    width = 1 if single else simd.lanes(_step(free, fixed, observer))
    lanes = (f"-DLANES={width}",) if width else ()
    return _load(source, name, (*simd.FLAGS, *lanes)) or _load(source, name, ("-O2", *lanes))


def _split(vector: np.ndarray, free: Sequence[str] | None) -> tuple[tuple[int, ...], tuple[float, ...]]:
    """``(free indices, fixed values)`` of a parameter vector: the key of its compiled replay, shared by :func:`prepare` and :func:`replay`."""
    names = PlantParameters.names()
    free_idx = tuple(range(len(names))) if free is None else tuple(names.index(n) for n in free)
    return free_idx, tuple(0.0 if i in free_idx else float(v) for i, v in enumerate(vector))


def sample_period(t: np.ndarray) -> float:
    """The step between the samples at times ``t``: their median step to 12 digits (a 1 kHz log's is 0.001 whatever
    its times' rounding). Not the first step: a log whose first was 4.5 % long fitted the force gain 8 % low."""
    return float(f"{np.median(np.diff(t)):.12g}") if len(t) > 1 else 1e-3


def _key(vectors: np.ndarray, t: np.ndarray, free: Sequence[str] | None) -> tuple[tuple, np.ndarray, float]:
    """For :func:`replay` and :func:`observe`: the compiled step's key (sub-steps, free, fixed), the sets' free parameters, the sub-step."""
    period = sample_period(t)
    n_sub = substeps(period, MAX_SUBSTEP)
    free_idx, fixed = _split(vectors[0], free)
    return (n_sub, free_idx, fixed), np.ascontiguousarray(vectors[:, free_idx]), period / n_sub


def _pointer(a: np.ndarray):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def _in_vm(one: ca.Function, x0: np.ndarray, per_sample: list, P: np.ndarray, h: float) -> list[np.ndarray]:
    """Without a compiler: ``one`` in CasADi's VM, set by set, outputs ``(m, n, size)``; ``per_sample``: inputs between state and parameters."""
    n = per_sample[0].shape[1]
    f = one.mapaccum("in_vm", n)  # the state (first input, first output) carried from sample to sample
    rows = [f(x0, *per_sample, ca.repmat(ca.DM(theta), 1, n), ca.repmat(h, 1, n)) for theta in P]
    rows = [r if isinstance(r, (list, tuple)) else [r] for r in rows]
    return [np.stack([np.asarray(r[i]).T for r in rows]) for i in range(len(rows[0]))]


def prepare(params: PlantParameters, periods: Sequence[float], free: Sequence[str]) -> bool:
    """Build (or load) the compiled replay and observer for each sample period ahead of use; whether the observer
    runs as compiled C for every period (else in CasADi's virtual machine, many times slower)."""
    free_idx, fixed = _split(np.asarray(params.as_vector(), dtype=float), free)
    compiled = True
    for n_sub in sorted({substeps(period, MAX_SUBSTEP) for period in periods}):
        for single in (False, True):  # batches, and the check's lone set
            _compiled(n_sub, free_idx, fixed, single=single)
        compiled &= _compiled(n_sub, free_idx, fixed, 2 if params.Mp > 0 else 1) is not None  # the search's observer
    return compiled


def replay(params: list[PlantParameters] | np.ndarray, V: np.ndarray, t: np.ndarray, x0: np.ndarray, restarts: dict[int, np.ndarray] | None = None, *,
           free: Sequence[str] | None = None) -> np.ndarray:
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
        ``{k: state}``: the replay continues from ``state`` at ``t[k]`` (before step ``k``); a nan speed keeps the replay's own speeds.
    free : sequence of str, optional
        The parameters that differ between the sets (default: all). The others take the first set's values, compiled in as constants (faster).

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
    key, P, h = _key(vectors, t, free)
    V, t, x0 = (np.ascontiguousarray(a, dtype=float) for a in (V, t, x0))
    r, sr = np.zeros(n), np.zeros((n, 4))
    for k, state in (restarts or {}).items():
        if 0 <= k < n:
            r[k], sr[k] = (2.0 if np.isnan(state[1]) else 1.0), np.nan_to_num(state)  # a nan speed: the replay's own
    run = _compiled(*key, single=m == 1)
    if run is None:
        return _in_vm(_sample(*key), x0, [V[None], t[None], r[None], sr.T], P, h)[0]
    states = np.empty((m, n, 4))
    run(ctypes.c_int(m), ctypes.c_int(n), *map(_pointer, (x0, V, t, r, sr, P)), ctypes.c_double(h), _pointer(states))
    return states


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

    The replay of :func:`replay`, corrected after each sample towards the logged outputs ``y[k]`` (the position ``(n,)``, or the position and the
    angle ``(n, 2)``): ``state <- predicted + gain @ (y[k] - predicted outputs)`` with ``gain`` ``(4,)`` or ``(4, 2)`` (why:
    :mod:`pendulab.calibration._observer`). ``gain = 0`` is the replay itself. With ``states=True`` the corrected states ``(m, n, 4)`` too (the
    observer's estimate of the state after each sample). Arguments as :func:`replay`, with ``params`` an array ``(m, n_params)``.

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
    Y = np.ascontiguousarray(np.asarray(y, dtype=float).reshape(n, -1))
    ny = Y.shape[1]
    key, P, h = _key(vectors, t, free)
    V, t, x0 = (np.ascontiguousarray(a, dtype=float) for a in (V, t, x0))
    g = np.asarray(gain, dtype=float).reshape(4, ny).T.ravel().copy()  # column-major (4 x ny), as CasADi's
    run = _compiled(*key, ny, single=m == 1)
    if run is None:
        corrected, predicted, _ = _in_vm(_sample(*key, ny), x0, [V[None], t[None], Y.T, ca.repmat(ca.DM(g).reshape((4, ny)), 1, n)], P, h)
    else:
        predicted, corrected = np.empty((m, n, ny)), np.empty((m, n, 4))
        run(ctypes.c_int(m), ctypes.c_int(n), *map(_pointer, (x0, V, t, Y, g, P)), ctypes.c_double(h), _pointer(predicted), _pointer(corrected))
    out = predicted[:, :, 0] if np.ndim(y) == 1 else predicted
    return (out, corrected) if states else out
