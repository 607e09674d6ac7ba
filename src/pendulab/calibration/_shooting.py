"""Numerical core of the least-squares fit: shooting intervals, compiled evaluation, sparse Jacobian.

The NLP that :func:`pendulab.calibration.fit.fit_parameters` hands to IPOPT is a (bounded)
nonlinear least-squares problem ``min 1/2 |r(w)|^2`` over ``w = [theta; nodes]``. Everything heavy
happens in one CasADi function per shooting interval (``n`` logged samples of RK4 steps) and its
Jacobian with respect to the interval's start state and the parameters, both mapped over all
intervals. They are generated as C, compiled once per machine (cached by a hash of the source) and
loaded with ``casadi.external``; without a C compiler CasADi's virtual machine evaluates them
instead (about ten times slower).

The residual vector and its sparse Jacobian are assembled in numpy and handed to IPOPT through
``casadi.Callback`` objects that cache the last point, so that the objective gradient and the
Gauss-Newton Hessian ``J^T J`` of one iteration share one Jacobian evaluation.
"""

from __future__ import annotations

import hashlib
from typing import Sequence

import casadi as ca
import numpy as np
import scipy.sparse as sp

from pendulab.native import shared_library


def _compile(functions: Sequence[ca.Function], name: str, optimize: str = "-O1", flags: Sequence[str] = ()) -> tuple[str | None, bool]:
    """Shared library holding ``functions`` (built once, cached by :func:`pendulab.native.shared_library`)
    and whether it was built just now; ``(None, False)`` without a working compiler."""
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for f in functions:
        gen.add(f)
    library = shared_library(gen.dump(), name, flags=(optimize, *flags), salt=ca.__version__, kind="fit", prebuilt=False)
    return (str(library.path), library.built) if library else (None, False)


class IntervalFunctions:
    """The interval function ``F`` and its Jacobian ``G`` for one problem structure.

    ``F(s0, V[n], h[n], t[n], theta, scales) -> (end[ns], y[n_out*n])``;
    ``G(...) -> (end, y, dy/d[s0;theta], dend/d[s0;theta])``. The parameters that are not fitted are
    compiled in as constants (``p0``): the cart alone then loses every pendulum term, which halves
    the code.
    """

    def __init__(
        self,
        rk4: ca.Function,
        n_steps: int,
        n_sub: int,
        n_states: int,
        fitted_idx: Sequence[int],
        p0: Sequence[float],
        with_alpha: bool,
        compile: bool | None = None,
    ) -> None:
        self.n_steps, self.n_states, self.n_theta = n_steps, n_states, len(fitted_idx)
        self.n_out = 2 if with_alpha else 1
        s0 = ca.SX.sym("s0", n_states)
        V, h, t = ca.SX.sym("V", n_steps), ca.SX.sym("h", n_steps), ca.SX.sym("t", n_steps)
        theta, scales = ca.SX.sym("theta", len(fitted_idx)), ca.SX.sym("scales", len(fitted_idx))
        entries = [ca.SX(float(v)) for v in p0]
        for j, i in enumerate(fitted_idx):
            entries[i] = theta[j] * scales[j]
        pfull = ca.vertcat(*entries)
        state = s0 if n_states == 4 else ca.vertcat(s0, 0, 0)
        outputs = []
        for k in range(n_steps):
            hs = h[k] / n_sub
            for i in range(n_sub):
                state = rk4(state, V[k], pfull, t[k] + i * hs, hs)
            outputs.append(state[0])
            if with_alpha:
                outputs.append(state[2])
        end = state if n_states == 4 else state[:2]
        y = ca.vertcat(*outputs)
        inputs = [s0, V, h, t, theta, scales]
        z = ca.vertcat(s0, theta)
        fixed = [0.0 if i in fitted_idx else float(v) for i, v in enumerate(p0)]  # fitted values are inputs
        key = hashlib.sha256(repr((n_steps, n_sub, n_states, with_alpha, tuple(fitted_idx), fixed)).encode())
        tag = key.hexdigest()[:10]
        F = ca.Function(f"fit_interval_{tag}", inputs, [end, y])
        G = ca.Function(f"fit_interval_jac_{tag}", inputs, [end, y, ca.jacobian(y, z), ca.jacobian(end, z)])
        self.compiled = self.built = False
        library = None
        if compile is not False:
            library, self.built = _compile([F, G], f"pendulab_fit_{tag}")
        if library:
            self.F, self.G = ca.external(F.name(), library), ca.external(G.name(), library)
            self.compiled = True
        else:
            self.F, self.G = F, G

    def mapped(self, N: int) -> tuple[ca.Function, ca.Function]:
        """``F`` and ``G`` mapped over ``N`` intervals."""
        cache = self.__dict__.setdefault("_mapped", {})
        if N not in cache:
            cache[N] = (self.F.map(N, "serial"), self.G.map(N, "serial"))
        return cache[N]


class LogBlock:
    """One log inside the problem: its intervals, measured data and place in ``w`` and ``r``.

    Residual layout: ``[data (n_out*M*N, interval-major); first samples (n_out); defects (ns*N)]``.
    """

    def __init__(self, log, M: int, functions: IntervalFunctions, offset_w: int, offset_r: int, sigma: np.ndarray,
                 sigma_defect: np.ndarray, nodes0: np.ndarray) -> None:
        self.log = log
        self.M, self.N = M, (len(log) - 1) // M
        self.used = self.N * self.M + 1
        self.f = functions
        self.ns, self.n_out, self.nt = functions.n_states, functions.n_out, functions.n_theta
        N, used = self.N, self.used
        self.V = log.V[: used - 1].reshape(N, M).T
        self.h = np.diff(log.t[:used]).reshape(N, M).T
        self.t = log.t[: used - 1].reshape(N, M).T
        data = [log.x[:used]] + ([log.alpha[:used]] if self.n_out == 2 else [])
        self.first = np.array([d[0] for d in data])
        # Measured outputs after each step, interleaved like y: (n_out*M, N).
        self.measured = np.stack([d[1:].reshape(N, M) for d in data], axis=2).reshape(N, M * self.n_out).T
        self.sigma = sigma  # (n_out,) measurement noise
        self.sigma_y = np.tile(sigma, M)  # per row of y
        self.sigma_defect = sigma_defect  # (ns,)
        self.offset_w, self.offset_r = offset_w, offset_r
        self.n_w = self.ns * (N + 1)
        self.n_data = self.n_out * M * N
        self.n_r = self.n_data + self.n_out + self.ns * N
        self.nodes0 = nodes0  # (N+1, ns)

    def nodes(self, w: ca.MX) -> ca.MX:
        return ca.reshape(w[self.offset_w : self.offset_w + self.n_w], self.ns, self.N + 1)

    def residuals(self, S: ca.MX, ends: ca.MX, y: ca.MX) -> ca.MX:
        data = ca.vec(ca.mtimes(ca.diag(ca.DM(1.0 / self.sigma_y)), y - self.measured))
        first = (S[[0, 2][: self.n_out], 0] - self.first) / self.sigma
        defects = ca.vec(ca.mtimes(ca.diag(ca.DM(1.0 / self.sigma_defect)), ends - S[:, 1:]))
        return ca.vertcat(data, first, defects)

    def pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """Rows and columns of this block's Jacobian entries, in the order of :meth:`values`."""
        ns, nt, N, rows_y = self.ns, self.nt, self.N, self.n_out * self.M
        c = np.arange(N * (ns + nt))
        k, j = c // (ns + nt), c % (ns + nt)
        col = np.where(j < ns, self.offset_w + k * ns + j, j - ns)  # a node's state, or a parameter
        r_data = (self.offset_r + k * rows_y)[:, None] + np.arange(rows_y)[None, :]
        c_data = np.broadcast_to(col[:, None], r_data.shape)
        r_first = self.offset_r + self.n_data + np.arange(self.n_out)
        c_first = self.offset_w + np.array([0, 2][: self.n_out])
        base_def = self.offset_r + self.n_data + self.n_out
        r_def = (base_def + k * ns)[:, None] + np.arange(ns)[None, :]
        c_def = np.broadcast_to(col[:, None], r_def.shape)
        kk = np.arange(N)
        r_next = (base_def + kk * ns)[:, None] + np.arange(ns)[None, :]
        c_next = (self.offset_w + (kk + 1) * ns)[:, None] + np.arange(ns)[None, :]
        rows = np.concatenate([r_data.ravel(), r_first, r_def.ravel(), r_next.ravel()])
        cols = np.concatenate([c_data.ravel(), c_first, c_def.ravel(), c_next.ravel()])
        return rows, cols

    def values(self, Jy: ca.MX, Je: ca.MX) -> ca.MX:
        """Jacobian entries in :meth:`pattern` order (column-major ``vec`` of the mapped blocks)."""
        Jy = ca.mtimes(ca.diag(ca.DM(1.0 / self.sigma_y)), Jy)
        Je = ca.mtimes(ca.diag(ca.DM(1.0 / self.sigma_defect)), Je)
        first = ca.DM(1.0 / self.sigma)
        nxt = ca.DM(np.tile(-1.0 / self.sigma_defect, self.N))
        return ca.vertcat(ca.vec(Jy), first, ca.vec(Je), nxt)


class Problem:
    """The least-squares problem ``r(w)``, ``J(w)`` of the whole fit as CasADi expressions.

    ``residuals`` evaluates only the interval functions (for the objective and line searches);
    ``residuals_jac`` and ``jacobian`` share one evaluation of their Jacobians.
    """

    def __init__(self, blocks: list[LogBlock], n_theta: int, scales: np.ndarray, theta0: np.ndarray, prior_weight: float) -> None:
        self.blocks, self.nt = blocks, n_theta
        self.n_w = n_theta + sum(b.n_w for b in blocks)
        self.n_r = sum(b.n_r for b in blocks) + n_theta
        self.w = ca.MX.sym("w", self.n_w)
        theta = self.w[:n_theta]
        prior = np.sqrt(prior_weight)
        rows, cols = [], []
        for b in blocks:
            r, c = b.pattern()
            rows.append(r)
            cols.append(c)
        rows.append(self.n_r - n_theta + np.arange(n_theta))
        cols.append(np.arange(n_theta))
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        order = sp.csc_matrix((np.arange(1, len(rows) + 1, dtype=float), (rows, cols)), shape=(self.n_r, self.n_w))
        order.sort_indices()
        if order.nnz != len(rows):  # pragma: no cover - a duplicate would be a layout bug
            raise RuntimeError("duplicate Jacobian entries in the fit layout")
        permutation = (order.data.astype(np.int64) - 1).tolist()
        self.sparsity = ca.Sparsity(self.n_r, self.n_w, order.indptr.tolist(), order.indices.tolist())

        r_plain, r_jac, values, outputs = [], [], [], []
        for b in blocks:
            F, G = b.f.mapped(b.N)
            S = b.nodes(self.w)
            args = (S[:, :-1], b.V, b.h, b.t, theta, ca.DM(scales))
            ends, y = F(*args)
            r_plain.append(b.residuals(S, ends, y))
            outputs.append(y)
            ends_j, y_j, Jy, Je = G(*args)
            r_jac.append(b.residuals(S, ends_j, y_j))
            values.append(b.values(Jy, Je))
        r_prior = prior * (theta - theta0)
        values.append(ca.DM(np.full(n_theta, prior)))
        self.residuals = ca.vertcat(*r_plain, r_prior)
        self.residuals_jac = ca.vertcat(*r_jac, r_prior)
        self.jacobian = ca.MX(self.sparsity, ca.vertcat(*values)[permutation])
        self.outputs = outputs

    def split(self, w: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
        theta = w[: self.nt]
        nodes = [w[b.offset_w : b.offset_w + b.n_w].reshape(b.N + 1, b.ns).T for b in self.blocks]
        return theta, nodes
