"""The one way to simulate a run: :func:`simulate` a :class:`~pendulab.spec.RunSpec`.

Examples
--------
>>> import tempfile
>>> import pendulab
>>> from pendulab.control import demo_controller
>>> spec = pendulab.RunSpec(demo_controller("long"), timing=pendulab.Timing(stop_time=2.0))
>>> result = pendulab.simulate(spec)
>>> result.metrics["stable"], len(result.columns["t"])
(True, 2001)
>>> sorted(result.write(tempfile.mkdtemp()))
['csv', 'mat', 'metrics']
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from pendulab.errors import UserError
from pendulab.spec import RunSpec


class _BuiltOnUse:
    """A dataclass field holding a dict, or a function that builds it on first read (None: an empty dict)."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.slot = f"_{name}"

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return None  # the field's default
        value = obj.__dict__[self.slot]
        if callable(value):
            value = obj.__dict__[self.slot] = value()
        return value

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.slot] = {} if value is None else value


@dataclass
class SimulationResult:
    """Columns of a run (SPEC §7 names), its metrics and its metadata.

    Attributes
    ----------
    columns : dict of str to ndarray
        ``t``, ``x``, ``xdot``, ``alpha``, ``alpha_measured``, ``tip``, ``voltage_command``, ``voltage``,
        ``supervisor_state`` (and any signals recorded on request, under their full names).
    metrics : dict
        What ``metrics.json`` holds (:func:`pendulab.analysis.verdict.assess`: the response metrics where
        they mean something, the cut's reason and the verdict).
    meta : dict
        What the ``meta`` struct of ``run.mat`` holds.
    spec : RunSpec or None
        The run's description.
    verdict : pendulab.analysis.verdict.Verdict or None
        Balanced, cut or fell, and the warnings (:mod:`pendulab.analysis.verdict`); the first line
        ``pendulab simulate`` prints is ``verdict.headline()``.

    Examples
    --------
    >>> import pendulab
    >>> result = pendulab.simulate(pendulab.RunSpec(pendulab.demo_controller(), timing=pendulab.Timing(stop_time=1.5)))
    >>> sorted(result.columns)[:3], result.meta["run"] == result.spec.to_json()
    (['alpha', 'alpha_measured', 'supervisor_state'], True)
    """

    columns: dict[str, np.ndarray]
    metrics: dict[str, Any]
    meta: dict[str, Any] = _BuiltOnUse()  # type: ignore[assignment]
    spec: RunSpec | None = None
    verdict: Any = None

    def __getstate__(self) -> dict[str, Any]:
        self.meta  # noqa: B018 - built before pickling (a function cannot be pickled)
        return self.__dict__

    def write(self, out_dir: str | os.PathLike[str]) -> dict[str, Path]:
        """Write ``run.mat``, ``run.csv`` and ``metrics.json`` into ``out_dir``; returns their paths by kind."""
        from pendulab.analysis.results import write_results

        return write_results(out_dir, self.columns, self.meta, self.metrics)


def simulate(
    spec: RunSpec,
    *,
    progress: Callable[[float], None] | None = None,
    events: Sequence[Any] = (),
    record: Sequence[str] = (),
    meta: Mapping[str, Any] | None = None,
    fmu_dir: str | os.PathLike[str] | None = None,
    simulator: "Simulator | None" = None,
) -> SimulationResult:
    """Simulate the lab's loop (plant, controller, supervisor FMUs) as ``spec`` describes, and measure the poke.

    Parameters
    ----------
    spec : RunSpec
        The run; it is validated first (a broken rule raises :class:`~pendulab.errors.UserError`).
    progress : callable, optional
        Called with the simulated time now and then.
    events : sequence of pendulab.cosim.master.Event, optional
        Inputs set at given times (e.g. supervisor commands).
    record : sequence of str, optional
        Extra signals (``"controller.xdot_estimate"``) returned in ``columns`` under their full names.
    meta : mapping, optional
        Entries added to the result's ``meta`` (e.g. a calibration's label).
    fmu_dir : path, optional
        Folder of the Plant, Controller and Supervisor FMUs (default: the package's, built if missing).
    simulator : Simulator, optional
        FMU instances kept from an earlier run, reset for this one instead of loading the FMUs again
        (a sweep's worker runs thousands of runs this way); default: load them for this run alone.

    Returns
    -------
    SimulationResult

    Raises
    ------
    pendulab.errors.UserError
        The spec breaks a rule.
    pendulab.cosim.master.SimulationError
        An FMU refused a step (e.g. a poke so large that the state overflows).

    Examples
    --------
    >>> import pendulab
    >>> spec = pendulab.RunSpec(pendulab.pid(600, 200, 5), poke=pendulab.Poke(220.0, 0.005, 0.5),
    ...                         timing=pendulab.Timing(stop_time=1.5, delay=2))
    >>> result = pendulab.simulate(spec)
    >>> float(result.columns["t"][-1]), result.metrics["peak_time_s"] < 0.1
    (1.5, True)
    """
    from pendulab.analysis.verdict import Limits, assess
    from pendulab.cosim.master import Master, SimulationError
    from pendulab.cosim.pendulum import RECORDED, collect_columns

    modes = spec.supervisor.recentre or spec.supervisor.swing_up
    # The modes' signals are recorded (and written) only in runs that use a mode: other runs' files are as before.
    mode_recorded = tuple(MODE_COLUMNS) if modes else ()

    spec.validate()
    if spec.plant.kind == "seesaw":
        from pendulab.cosim.seesaw import simulate_seesaw

        return simulate_seesaw(spec, progress=progress, events=events, record=record, meta=meta, fmu_dir=fmu_dir)
    params = spec.parameters()
    timing = spec.timing
    block = spec.controller.fmu
    fmu_path = Path(fmu_dir) if fmu_dir is not None else None
    if simulator is None:
        context: Any = Master(build_system(spec, params, fmu_dir=fmu_path))
    else:
        context = contextlib.nullcontext(simulator.master(build_system(spec, params, fmu_dir=fmu_path, cache=simulator.cache)))
    with context as master:
        try:
            log = master.run(timing.stop_time, [*RECORDED, *mode_recorded, *record], events=tuple(events), progress=progress)
        except SimulationError as exc:
            if block is not None:
                from pendulab.blocks.base import block_error

                detail = block_error("controller")
                if detail:
                    raise SimulationError(f"{exc}: {detail}") from exc
            raise
    columns = collect_columns(log, params)
    safety_cut = columns.pop("_safety_cut_time")
    for path, name in MODE_COLUMNS.items():
        if path in mode_recorded:
            columns[name] = np.asarray(log[path], dtype=float)
    if spec.supervisor.swing_up:
        # The pendulum may turn over while it swings: angles from upright, in (-pi, pi] as the supervisor sees them.
        for name in ("alpha", "alpha_measured"):
            columns[name] = np.remainder(columns[name] + np.pi, 2 * np.pi) - np.pi
        columns["tip"] = params.Lp * columns["alpha"]
    moments: dict[str, Any] = {}
    if modes:
        from pendulab.analysis.modes import mode_events, mode_metrics

        moments = mode_metrics(columns["t"], columns["supervisor_state"], recentring=columns["recentring"], x=columns["x"])
    # A swing-up run's response is measured from the catch on (the hand-over is its disturbance).
    start = moments.get("catch_time_s") if spec.supervisor.swing_up else None
    first = 0 if start is None else int(np.searchsorted(columns["t"], start))
    metrics, verdict = assess(
        {name: values[first:] for name, values in columns.items()}, poke_start=params.poke_start if start is None else start,
        limits=Limits.of(params, spec.supervisor_parameters()), poke=(params.poke_magnitude, params.poke_duration),
        safety_cut_time=safety_cut, recentre=spec.supervisor.recentre, caught=start is not None,
    )
    metrics.update(moments)
    for name in record:
        columns[name] = np.asarray(log[name])
    extra = dict(meta or {})
    if modes:
        extra = {"recentre": spec.supervisor.recentre, "swing_up": spec.supervisor.swing_up, "start": spec.plant.start,
                 "mode_events": mode_events(columns["t"], columns["supervisor_state"], recentring=columns["recentring"]), **extra}

    def info() -> dict[str, Any]:
        return {**run_meta(spec, params), **extra}

    # The meta (the spec's JSON among it) is built when it is first read: a sweep's runs never read it.
    return SimulationResult(columns, metrics, info, spec, verdict)


class Simulator:
    """FMU instances that :func:`simulate` resets and reuses from one run to the next.

    The first run loads and instantiates the FMUs; each later run resets them (``fmi2Reset``) and sets
    its own start values, which gives the same result, bit for bit, as loading them afresh. Runs must
    use the same FMUs (the same kind of controller). Use as a context manager.

    Examples
    --------
    >>> import pendulab
    >>> from pendulab.control import Controller
    >>> with Simulator() as sim:
    ...     results = [pendulab.simulate(pendulab.RunSpec(Controller.pid(kp, 20, 10), timing=pendulab.Timing(stop_time=2.0)),
    ...                                  simulator=sim) for kp in (600, 750, 1200)]
    >>> [r.metrics["stable"] for r in results]
    [True, True, True]
    """

    def __init__(self) -> None:
        self._master: Any = None
        #: What :func:`build_system` looks up once: the FMUs' paths, each controller's realization.
        self.cache: dict[Any, Any] = {}

    def master(self, system: Any) -> Any:
        """The :class:`~pendulab.cosim.master.Master` for ``system``: loaded on first use, else reset to it."""
        from pendulab.cosim.master import Master

        if self._master is None:
            self._master = Master(system)
        else:
            self._master.reset(system)
        return self._master

    def close(self) -> None:
        """Free the instances (the next run loads the FMUs again)."""
        if self._master is not None:
            self._master.close()
            self._master = None

    def __enter__(self) -> "Simulator":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def build_system(spec: RunSpec, params: Any, *, fmu_dir: Path | None = None, cache: dict[Any, Any] | None = None) -> Any:
    """The co-simulation system (:class:`pendulab.cosim.system.System`) of a run.

    One branch per ``spec.plant.kind`` and controller kind; a new plant adds its branch here.
    ``cache`` (kept by a :class:`Simulator`) remembers the FMUs' paths and each controller's discrete
    realization across runs.
    """
    from pendulab.cosim.pendulum import pendulum_system

    timing = spec.timing
    supervisor = spec.supervisor_parameters()
    if spec.plant.kind == "seesaw":
        from pendulab.control.state_feedback import realize_state_feedback
        from pendulab.cosim.seesaw import seesaw_system

        block = realize_state_feedback(spec.controller.state_feedback, timing.step, timing.method)
        return seesaw_system(params, block.to_parameters(), step=timing.step, supervisor=supervisor, fmu_dir=fmu_dir,
                             delay=timing.delay)
    if spec.controller.fmu is not None:
        from pendulab.blocks.loop import block_controller_system

        if spec.initial_state():
            raise UserError("a pendulum that starts hanging needs a G(s) controller (the Controller FMU); "
                            "a controller block starts upright")

        return block_controller_system(spec.controller.fmu, params, step=timing.step, supervisor=supervisor,
                                       controller_parameters=dict(spec.controller.parameters), fmu_dir=fmu_dir,
                                       delay=timing.delay)
    from pendulab.control.realization import discretize

    fmus = None
    if cache is None:
        realized = discretize(spec.controller.transfer_function, h=timing.step, method=timing.method).to_parameters()
    else:
        from pendulab.fmu.build import ensure_fmu

        fmus = cache.get("fmus")
        if fmus is None:
            fmus = cache["fmus"] = {name: ensure_fmu(name, fmu_dir) for name in ("Plant", "Controller", "Supervisor")}
        key = ("realized", json.dumps(spec.controller.transfer_function.to_dict()), timing.step, timing.method)
        realized = cache.get(key)
        if realized is None:
            if len(cache) > 64:  # a sweep's points come one after another: the recent ones are enough
                for old in [k for k in cache if k != "fmus"][:32]:
                    del cache[old]
            realized = cache[key] = discretize(spec.controller.transfer_function, h=timing.step, method=timing.method).to_parameters()
    return pendulum_system(params, realized, step=timing.step, supervisor=supervisor, fmu_dir=fmu_dir,
                           delay=timing.delay, initial_state=spec.initial_state(), fmus=fmus)


#: The supervisor modes' signals (runs with re-centring or swing-up) -> their columns.
MODE_COLUMNS = {"supervisor.r": "reference", "supervisor.recentring": "recentring", "supervisor.misses": "missed_catches"}


def run_meta(spec: RunSpec, params: Any) -> dict[str, Any]:
    """The ``meta`` struct of a run's files: the spec's serialization and what it resolves to.

    ``run`` is :meth:`RunSpec.to_json` (``RunSpec.from_json(meta["run"])`` gives the spec back; MATLAB
    reads it with ``jsondecode(meta.run)``); the other fields are the SPEC's (controller written out,
    the plant's parameters, calibration, pendulum, version) and the timing.
    """
    from pendulab import __version__

    meta: dict[str, Any] = {"controller": spec.describe_controller()}
    if spec.controller.fmu is None:
        meta["discretization"] = spec.timing.method
    if spec.plant.kind != "pendulum":
        meta["plant"] = spec.plant.kind
    meta.update(
        step=spec.timing.step,
        delay=spec.timing.delay,
        parameters=params.as_dict(),
        version=__version__,
        pendulum=spec.plant.pendulum if spec.plant.kind == "pendulum" else "none",
        cart=spec.plant.cart,
        calibration=spec.plant.calibration or "default",
        run=spec.to_json(),
    )
    return meta
