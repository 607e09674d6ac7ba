"""Runs of a sweep in one process: the three FMUs loaded once, reset between runs.

:class:`BatchRunner` is what each worker process holds. Its first run unpacks and instantiates the
plant, controller and supervisor FMUs (:class:`~pendulab.cosim.master.Master`); every later run
resets them (``fmi2Reset``), sets the run's start values (plant parameters, controller matrices,
delay) and steps the loop with the master's compiled plan runner: each run is ``pendulab.simulate``
of its RunSpec with a :class:`~pendulab.simulation.Simulator`. A reset instance gives the same
trajectory, bit for bit, as a freshly loaded one (``tests/test_sweep.py``).

Each run ends with a status (:data:`STATUSES`): the verdict of its response (balanced, cut, fell),
with the supervisor's reason for a cut and the verdict's warnings beside it,
``error`` when the run could not be simulated (an FMU failed, a parameter was out of range), or
``timeout`` when it took longer than the sweep's per-run time budget.

Examples
--------
>>> from pendulab.sweep.spec import parse_sweep_spec, runs_of
>>> spec = parse_sweep_spec("[run]\\nstop_time = 2\\n[controller]\\ndemo = true")
>>> # skipped: the sweep's own tests (tests/test_sweep.py) run batches
>>> with BatchRunner() as runner:                                   # doctest: +SKIP
...     row = runner.run(spec, *next(runs_of(spec)))
>>> row["status"]                                                   # doctest: +SKIP
'balanced'
"""

from __future__ import annotations

import os
import socket
import time
from typing import Any, Mapping

from pendulab.errors import UserError

#: The status of a run: its verdict's outcome (:mod:`pendulab.analysis.verdict`), or why it has none.
STATUSES = ("balanced", "cut", "fell", "not tested", "error", "timeout")


def verdict(metrics: Mapping[str, Any]) -> str:
    """The status of a run that was simulated: the outcome of its verdict (``metrics["verdict"]``).

    ``balanced``, ``cut`` (the supervisor cut the motor with the pendulum still up, e.g. at the track
    limit), ``fell`` (past the angle limit) or ``not tested`` (no poke), as ``pendulab simulate`` prints it.
    """
    return str(metrics["verdict"]["outcome"])


class RunTimeout(Exception):
    """A run went past its time budget."""


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def blank_row(spec: Any, run_id: int, point: int, sample: int, inputs: Mapping[str, Any], status: str, message: str = "",
              seconds: float = 0.0) -> dict[str, Any]:
    """A result row without metrics (a run that failed, timed out or crashed its worker)."""
    from pendulab.analysis.metrics import METRIC_KEYS

    return {"run_id": run_id, "point": point, "sample": sample, **{n: inputs.get(n) for n in spec.input_names},
            "status": status, "message": message, "safety_cut_reason": None, "warnings": None,
            **{k: None for k in METRIC_KEYS}, "time_s": seconds, "worker": worker_name()}


class BatchRunner:
    """Runs the runs of a sweep one after the other on one set of FMU instances (use as a context manager).

    Each run is its :class:`~pendulab.spec.RunSpec` given to :func:`pendulab.simulate` with this
    runner's :class:`~pendulab.simulation.Simulator`, which keeps the instances across runs.
    """

    def __init__(self) -> None:
        from pendulab.simulation import Simulator

        self._simulator = Simulator()

    def __enter__(self) -> "BatchRunner":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._simulator.close()

    def run(self, spec: Any, run_id: int, point: int, sample: int, inputs: Mapping[str, Any]) -> dict[str, Any]:
        """Simulate one run of ``spec`` with ``inputs`` (its grid values and drawn parameters) into a row."""
        from pendulab.cosim.master import SimulationError
        from pendulab.simulation import simulate

        started = time.perf_counter()
        deadline = started + spec.timeout

        def check(_t: float) -> None:
            if time.perf_counter() > deadline:
                raise RunTimeout

        try:
            metrics = simulate(spec.run_spec(inputs), progress=check, simulator=self._simulator).metrics
            status, message = verdict(metrics), ""
        except RunTimeout:
            self.close()  # the instances stopped mid-run: load them afresh for the next run
            status, message, metrics = "timeout", f"took longer than the sweep's timeout of {spec.timeout:g} s", {}
        except (SimulationError, UserError) as exc:
            self.close()
            status, message, metrics = "error", " ".join(str(exc).split()), {}
        except Exception as exc:  # noqa: BLE001 - any failure of one run is that run's status, not the sweep's end
            self.close()
            status, message, metrics = "error", f"{type(exc).__name__}: {' '.join(str(exc).split())}", {}
        row = blank_row(spec, run_id, point, sample, inputs, status, message)
        row.update({k: v for k, v in metrics.items() if k in row and k != "warnings"})
        if metrics:
            row["warnings"] = ",".join(w["kind"] for w in metrics["verdict"]["warnings"])
        row["time_s"] = time.perf_counter() - started
        return row
