"""The seesaw's loop as a co-simulation: Seesaw.fmu -> Controller.fmu (state feedback) -> Supervisor.fmu.

The same Controller and Supervisor FMUs as the pendulum's loop, wired by name to the seesaw:

- the controller is the two-input discrete LTI block (:func:`pendulab.control.state_feedback.realize_state_feedback`):
  the measured tilt into its angle input (``Lp = -1``, ``r = 0``: its error is the tilt itself), the measured
  cart position into ``x_measured``;
- the supervisor watches the tilt as it watches the pendulum's angle, with the seesaw's limits: the cart at
  +/-0.35 m (``setup_ip02_ssw.m``: ``X_MAX``) and the tilt at 10 degrees, before the seesaw rests on its
  tilt stop (11.5 degrees); and its start rule: a start only with the seesaw level (within the capture window).

Examples
--------
>>> import pendulab
>>> from pendulab.cosim.seesaw import seesaw_spec
>>> result = pendulab.simulate(seesaw_spec(stop_time=3.0))
>>> result.metrics["stable"], sorted(result.columns)[:3]
(True, ['supervisor_state', 't', 'theta'])
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from pendulab.cosim.system import System
from pendulab.fmu.build import ensure_fmu

#: The loop's wiring, by variable name.
CONNECTIONS = (
    ("seesaw.theta_measured", "controller.alpha_measured"),
    ("seesaw.x_measured", "controller.x_measured"),
    ("seesaw.theta_measured", "supervisor.alpha_measured"),
    ("seesaw.x_measured", "supervisor.x_measured"),
    ("controller.V_command", "supervisor.V_command"),
    ("supervisor.V", "seesaw.V"),
)
#: The seesaw's supervisor limits: the cart as in Quanser's lab (X_MAX = 0.35 m), the tilt at the low end
#: of the supervisor's settable range, short of the tilt stop.
SUPERVISOR_LIMITS = {"x_max": 0.35, "alpha_max": math.radians(10.0)}
#: The seesaw's start rule (Quanser's lab: hold it level, then start): a start is refused unless the tilt is within
#: the supervisor's capture window (2 degrees).
SUPERVISOR_START = {"level_start": True}
#: Recorded signals -> the column names of run.mat / run.csv.
RECORDED = {
    "seesaw.x": "x",
    "seesaw.xdot": "xdot",
    "seesaw.theta": "theta",
    "seesaw.theta_measured": "theta_measured",
    "seesaw.x_measured": "x_measured",
    "controller.V_command": "voltage_command",
    "seesaw.V_applied": "voltage",
    "supervisor.state": "supervisor_state",
    "supervisor.trip_reason": "trip_reason",
    "supervisor.trip_time": "trip_time",
}


def seesaw_spec(stop_time: float = 5.0, **sections: Any) -> Any:
    """The seesaw demo's run: Quanser's LQR (with its filters and integral) and a 5-degree tap at 1 s.

    Parameters
    ----------
    stop_time : float
        Length of the run (s).
    **sections
        Other RunSpec sections (``timing`` replaces ``stop_time``).
    """
    from pendulab.control.state_feedback import design_state_feedback
    from pendulab.spec import ControllerSpec, Plant, Poke, RunSpec, Timing

    sections.setdefault("timing", Timing(stop_time=stop_time))
    sections.setdefault("poke", Poke(*TAP_DEFAULT))
    return RunSpec(ControllerSpec(state_feedback=design_state_feedback("seesaw")), plant=Plant(kind="seesaw"), **sections)


def _tap_default() -> tuple[float, float, float]:
    from pendulab.model.seesaw import SeesawParameters

    f = SeesawParameters.__dataclass_fields__
    return (f["tap_magnitude"].default, f["tap_duration"].default, f["tap_start"].default)


#: The seesaw's tap (rad/s^2, s, s): about 5 degrees of tilt under Quanser's LQR.
TAP_DEFAULT = _tap_default()


def supervisor_start_values(supervisor: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The seesaw's Supervisor FMU start values: :data:`SUPERVISOR_LIMITS` and :data:`SUPERVISOR_START`, then the run's own settings."""
    return {**SUPERVISOR_LIMITS, **SUPERVISOR_START, **dict(supervisor or {})}


def verdict_limits(params: Any = None, supervisor: Mapping[str, Any] | None = None) -> Any:
    """The limits a seesaw run is judged against (:class:`pendulab.analysis.verdict.Limits`): the seesaw's
    tilt encoder step and tilt stop (``params``, default the courseware's), its supervisor's limits."""
    from pendulab.analysis.verdict import Limits
    from pendulab.model.seesaw import SeesawParameters

    return Limits.of(params if params is not None else SeesawParameters(), supervisor_start_values(supervisor))


def seesaw_system(
    params: Any,
    controller_parameters: Mapping[str, Any],
    *,
    step: float = 1e-3,
    supervisor: Mapping[str, Any] | None = None,
    fmu_dir: Path | None = None,
    delay: int = 0,
) -> System:
    """The seesaw's three-FMU system.

    Parameters
    ----------
    params : SeesawParameters
        The plant (its tap included).
    controller_parameters : mapping
        Start values of the Controller FMU (:meth:`StateFeedbackRealization.to_parameters`).
    supervisor : mapping, optional
        Supervisor start values over :data:`SUPERVISOR_LIMITS`.
    delay : int
        Transport delay in control periods before the seesaw's voltage input, as on the rig.
    """
    system = System(step=step)
    system.add("seesaw", ensure_fmu("Seesaw", fmu_dir), params.as_dict())
    system.add("controller", ensure_fmu("Controller", fmu_dir), {"h": step, **controller_parameters})
    system.add("supervisor", ensure_fmu("Supervisor", fmu_dir), supervisor_start_values(supervisor))
    for source, target in CONNECTIONS:
        system.connect(source, target, delay=delay if target == "seesaw.V" else 0)
    return system


def simulate_seesaw(
    spec: Any,
    *,
    progress: Callable[[float], None] | None = None,
    events: Sequence[Any] = (),
    record: Sequence[str] = (),
    meta: Mapping[str, Any] | None = None,
    fmu_dir: str | Path | None = None,
) -> Any:
    """:func:`pendulab.simulate` of a validated seesaw spec (``spec.plant.kind == "seesaw"``), judged as a seesaw
    (:func:`pendulab.analysis.verdict.assess` with ``plant="seesaw"``)."""
    from pendulab.analysis.results import SEESAW_COLUMNS
    from pendulab.analysis.verdict import assess
    from pendulab.cosim.master import Master
    from pendulab.simulation import SimulationResult, build_system, run_meta

    params = spec.parameters()
    timing = spec.timing
    system = build_system(spec, params, fmu_dir=Path(fmu_dir) if fmu_dir is not None else None)
    with Master(system) as master:
        log = master.run(timing.stop_time, [*RECORDED, *record], events=tuple(events), progress=progress)
    columns = {"t": np.asarray(log["time"], dtype=float)}
    columns.update({name: np.asarray(log[path], dtype=float) for path, name in RECORDED.items()})
    tripped = np.flatnonzero(columns["trip_reason"] > 0)
    safety_cut = float(columns["trip_time"][tripped[0]]) if tripped.size else None
    # The files have the seesaw's columns and, as the pendulum's, the supervisor's trip_reason.
    columns = {k: columns[k] for k in (*SEESAW_COLUMNS, "trip_reason")}
    metrics, verdict = assess(columns, poke_start=params.tap_start, limits=verdict_limits(params, spec.supervisor_parameters()),
                              poke=(params.tap_magnitude, params.tap_duration), safety_cut_time=safety_cut, plant="seesaw")
    for name in record:
        columns[name] = np.asarray(log[name])
    info = run_meta(spec, params)
    info.update(meta or {})
    return SimulationResult(columns, metrics, info, spec, verdict)
