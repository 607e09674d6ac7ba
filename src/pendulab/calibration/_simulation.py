"""Fast batch simulation of the CasADi plant over a logged voltage (one call per trajectory).

:meth:`pendulab.model.plant.PlantModel.simulate` steps in a Python loop; here the same step function
(RK4 sub-steps of the same right-hand side) is unrolled with ``mapaccum`` so that a whole trajectory,
or many trajectories with different parameters, is one CasADi call.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import MAX_SUBSTEP, step_function, substeps


@lru_cache(maxsize=64)
def _trajectory(n_steps: int, n_sub: int, n_parallel: int) -> ca.Function:
    accum = step_function(False, n_sub).expand().mapaccum("plant_steps", n_steps)
    # Wrap it so that p and h are one column each: map() then splits them per trajectory correctly.
    x0, V, t = ca.MX.sym("x0", 4), ca.MX.sym("V", 1, n_steps), ca.MX.sym("t", 1, n_steps)
    p, h = ca.MX.sym("p", len(PlantParameters.names())), ca.MX.sym("h")
    states = accum(x0, V, ca.repmat(p, 1, n_steps), t, ca.repmat(h, 1, n_steps))
    f = ca.Function("plant_trajectory", [x0, V, p, t, h], [states])
    return f.map(n_parallel) if n_parallel > 1 else f


def simulate_many(
    params: list[PlantParameters] | list[np.ndarray],
    V: np.ndarray,
    step: float,
    x0: np.ndarray,
    *,
    t0: float = 0.0,
    max_substep: float = MAX_SUBSTEP,
) -> np.ndarray:
    """States after each step for several parameter sets: array ``(len(params), n, 4)``.

    ``V[k]`` is held from ``t0 + k*step`` to ``t0 + (k+1)*step``; row ``k`` of the result is the state at
    ``t0 + (k+1)*step``.
    """
    V = np.asarray(V, dtype=float).ravel()
    n = len(V)
    vectors = np.column_stack([np.asarray(p.as_vector() if isinstance(p, PlantParameters) else p, dtype=float) for p in params])
    m = vectors.shape[1]
    n_sub = substeps(step, max_substep)
    f = _trajectory(n, n_sub, m)
    times = t0 + step * np.arange(n)
    x0 = np.asarray(x0, dtype=float).reshape(4, 1)
    out = f(np.tile(x0, (1, m)), np.tile(V[None, :], (1, m)), vectors, np.tile(times[None, :], (1, m)), step / n_sub)
    return np.asarray(out).reshape(4, m, n).transpose(1, 2, 0)


def simulate(params: PlantParameters, V: np.ndarray, step: float, x0=(0.0, 0.0, 0.0, 0.0), **kw) -> np.ndarray:
    """Like :meth:`PlantModel.simulate` (states at ``t = 0, step, ..., n*step``, shape ``(n+1, 4)``)."""
    states = simulate_many([params], V, step, np.asarray(x0, dtype=float), **kw)[0]
    return np.vstack([np.asarray(x0, dtype=float)[None, :], states])
