"""Sweeps: a grid of controllers over samples of plausible rigs, on one machine or a Dask cluster.

A sweep is a base run plus grid axes over the controller and distributions over the plant
(:mod:`pendulab.sweep.spec`). Its runs go in batches of about a second to worker processes that
hold the three FMUs loaded once (:mod:`pendulab.sweep.runner`, :mod:`pendulab.sweep.sandbox`), on
local processes or Dask (:mod:`pendulab.sweep.engines`); the rows are written in Parquet parts with a
journal as they come, so that a killed sweep resumes (:mod:`pendulab.sweep.store`), and end in
``DIR/results.parquet`` with plots.

Examples
--------
>>> import pendulab.sweep as ps
>>> spec = ps.parse_sweep_spec('''
... [run]
... stop_time = 3
... [controller.pid]
... kp = [600, 750]
... ki = 20
... kd = 10
... [uncertainty]
... samples = 4
... F1 = { uniform = [1.0, 2.0] }
... ''')
>>> # skipped: starts worker processes and writes sweep-out/ (tests/test_sweep.py runs sweeps)
>>> result = ps.sweep(spec, "sweep-out", workers=2)         # doctest: +SKIP
>>> result.counts                                            # doctest: +SKIP
{'balanced': 0, 'cut': 8, 'fell': 0, 'not tested': 0, 'error': 0, 'timeout': 0}
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from pendulab.sweep.runner import STATUSES, verdict
from pendulab.sweep.spec import SpecError, SweepSpec, load_sweep_spec, parse_sweep_spec, runs_of

__all__ = ["STATUSES", "Progress", "SpecError", "SweepResult", "SweepSpec", "load_sweep_spec", "parse_sweep_spec", "sweep", "verdict"]

#: Seconds of simulation work one batch aims at (a task per run would drown in the engine's overhead).
BATCH_SECONDS = 1.0
#: Rough cost of one 1 ms step of the three FMUs, to size the batches before anything has run.
STEP_SECONDS = 2.5e-6


@dataclass(frozen=True)
class Progress:
    """Where a sweep is: runs done (of ``total``), balanced among them, seconds since it started."""

    done: int
    total: int
    balanced: int
    new: int
    elapsed: float

    @property
    def rate(self) -> float:
        """Runs per second in this session (resumed runs not counted)."""
        return self.new / self.elapsed if self.elapsed > 0 else 0.0

    @property
    def remaining_s(self) -> float | None:
        return (self.total - self.done) / self.rate if self.rate > 0 else None


@dataclass(frozen=True)
class SweepResult:
    """A finished sweep: its folder, its table (``pyarrow.Table``), the count of each status."""

    out: Path
    table: Any
    counts: dict[str, int]
    elapsed: float
    engine: str
    plots: tuple[Path, ...] = ()


def batches_of(spec: SweepSpec, ids: list[int], workers: int) -> list[list[tuple]]:
    """The runs ``ids`` in batches of about :data:`BATCH_SECONDS`, at least four per worker."""
    if spec.batch:
        size = spec.batch
    else:
        per_run = spec.run["stop_time"] / spec.run["step"] * STEP_SECONDS + 1e-3
        size = max(1, round(BATCH_SECONDS / per_run))
        size = min(size, max(1, math.ceil(len(ids) / (4 * workers))))
    runs = list(runs_of(spec, ids))
    return [runs[i : i + size] for i in range(0, len(runs), size)]


def sweep(
    spec: SweepSpec | str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    resume: bool = False,
    overwrite: bool = False,
    plots: bool = True,
    progress: Callable[[Progress], None] | None = None,
    announce: Callable[[str], None] | None = None,
) -> SweepResult:
    """Run a sweep into the folder ``out``; ``DIR/results.parquet`` holds one row per run.

    Parameters
    ----------
    spec : SweepSpec or path
        The sweep (a path is read with :func:`load_sweep_spec`).
    scheduler : str, optional
        ``None``: local worker processes; ``"tcp://HOST:PORT"``: a Dask scheduler; ``"local:N"``: a
        Dask LocalCluster of N workers.
    workers : int, optional
        Local worker processes (default: one per core).
    resume : bool
        Continue the sweep in ``out`` (its journal): only the runs not yet recorded are run.
    overwrite : bool
        Replace an earlier sweep or run in ``out`` (refused without it).
    progress : callable, optional
        Called with a :class:`Progress` after each batch.
    announce : callable, optional
        Called with one line saying what will run where, once every check has passed and the engine is up.
    """
    from pendulab.sweep.engines import make_engine
    from pendulab.sweep.store import ResultStore

    text = None
    if not isinstance(spec, SweepSpec):
        text = Path(spec).read_text(encoding="utf-8") if Path(spec).is_file() else None
        spec = load_sweep_spec(spec)
    out = Path(out)
    ResultStore.check(out, spec, resume, overwrite)  # before any work, and before the folder exists
    started = time.perf_counter()
    with make_engine(scheduler, workers) as engine:
        if announce is not None:
            announce(f"sweep: {spec.n_points} controller point{'s' if spec.n_points != 1 else ''} x {spec.n_samples} plant "
                     f"sample{'s' if spec.n_samples != 1 else ''} = {spec.n_runs} runs of {spec.run['stop_time']:g} s on {engine.describe()}")
        store = ResultStore.open(out, spec, text or f"# {spec.source}\n{spec.to_toml()}", resume, overwrite)
        todo = [i for i in range(spec.n_runs) if i not in store.done]
        count = getattr(engine, "workers", None) or max(1, len(engine.client.scheduler_info().get("workers", {})))
        balanced = 0
        if resume and store.done:
            balanced = _count_balanced(store)
        new = 0
        for rows in engine.map(spec, batches_of(spec, todo, count)):
            before = len(store.done)
            store.add(rows)
            new += len(store.done) - before
            balanced += sum(1 for r in rows if r["status"] == "balanced")
            if progress is not None:
                progress(Progress(len(store.done), spec.n_runs, balanced, new, time.perf_counter() - started))
        description = engine.describe()
    path = store.finish()
    from pendulab.sweep.store import read_results

    table = read_results(out)
    statuses = table.column("status").to_pylist()
    counts = {s: statuses.count(s) for s in STATUSES}
    figures: tuple[Path, ...] = ()
    if plots:
        from pendulab.sweep.plots import plot_sweep

        figures = tuple(plot_sweep(spec, table, out / "plots"))
    del path
    return SweepResult(out, table, counts, time.perf_counter() - started, description, figures)


def _count_balanced(store: Any) -> int:
    import pyarrow.parquet as pq

    from pendulab.sweep.store import JOURNAL, _read_journal

    total = 0
    for entry in _read_journal(store.out / JOURNAL)[1:]:
        total += pq.read_table(store.out / entry["part"], columns=["status"]).column("status").to_pylist().count("balanced")
    return total
