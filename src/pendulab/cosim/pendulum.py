"""The lab's loop as a co-simulation: plant -> controller -> supervisor -> plant, and a poke run.

A run is simulated with :func:`pendulab.simulate`, which builds this system.

Examples
--------
>>> from pendulab.control import demo_controller, discretize
>>> from pendulab.cosim.pendulum import pendulum_system
>>> system = pendulum_system(PlantParameters.preset(), discretize(demo_controller(), h=1e-3).to_parameters())
>>> sorted(system.components)
['controller', 'plant', 'supervisor']
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np

from pendulab.cosim.system import System
from pendulab.errors import UserError
from pendulab.fmu.build import ensure_fmu
from pendulab.model.parameters import PlantParameters

#: The loop's wiring, by variable name (SPEC §7): the measured angle feeds controller and supervisor,
#: the supervisor owns the motor voltage, the controller's reference (re-centring) and its engagement
#: (swing-up). With both modes off, r stays 0 and the controller stays engaged: the loop of SPEC §4.
CONNECTIONS = (
    ("plant.alpha_measured", "controller.alpha_measured"),
    ("plant.alpha_measured", "supervisor.alpha_measured"),
    ("plant.x_measured", "supervisor.x_measured"),
    ("controller.V_command", "supervisor.V_command"),
    ("supervisor.V", "plant.V"),
    ("supervisor.r", "controller.r"),
    ("supervisor.controller_engaged", "controller.engaged"),
)
#: The supervisor-mode connections a controller FMU of another make may lack (then the modes are refused).
MODE_INPUTS = ("controller.r", "controller.engaged")

#: The plant FMUs the loop can name: the same model as FMI 2.0 (default) and FMI 3.0.
PLANT_FMUS = ("Plant", "Plant3")

#: The plant input the transport delay of the rig (``--delay N``) sits in front of.
VOLTAGE_INPUT = "plant.V"

#: Recorded signals -> the column names of run.mat / run.csv.
RECORDED = {
    "plant.x": "x",
    "plant.xdot": "xdot",
    "plant.alpha": "alpha",
    "plant.alpha_measured": "alpha_measured",
    "controller.V_command": "voltage_command",
    "plant.V_applied": "voltage",
    "supervisor.state": "supervisor_state",
    "supervisor.trip_reason": "trip_reason",
    "supervisor.trip_time": "trip_time",
}


def pendulum_system(
    params: PlantParameters,
    controller_parameters: Mapping[str, Any],
    *,
    step: float = 1e-3,
    supervisor: Mapping[str, Any] | None = None,
    initial_state: Mapping[str, float] | None = None,
    fmu_dir: Path | None = None,
    controller_fmu: Path | None = None,
    delay: int = 0,
    plant: str = "Plant",
    fmus: Mapping[str, Path] | None = None,
) -> System:
    """The standard three-FMU system.

    Parameters
    ----------
    controller_parameters : mapping
        Start values of the controller FMU (``n``, ``A[i,j]``, ``B[i]``, ``C[i]``, ``D``), as
        :meth:`pendulab.control.realization.DiscreteLTI.to_parameters` gives them.
    supervisor : mapping, optional
        Start values of the supervisor (``alpha_max``, ``x_max``, ...).
    controller_fmu : Path, optional
        Another controller FMU with the same interface (e.g. a Python block built with pythonfmu).
    delay : int, optional
        Transport delay in control periods between the supervisor's voltage and the plant, as on the
        rig (SPEC §9: the answer to sample k is applied at tick k + N). 0 (default): the voltage
        computed from the measurement at t_k acts from t_k on.
    plant : {"Plant", "Plant3"}
        The plant FMU: ``Plant`` (FMI 2.0, default) or ``Plant3`` (the same model as FMI 3.0, for export
        to other tools with :func:`pendulab.cosim.ssp.export_ssp`; pendulab's master runs FMI 2.0 FMUs).
    fmus : mapping, optional
        The FMUs' paths by name (``Plant``, ``Controller``, ``Supervisor``), already checked with
        :func:`~pendulab.fmu.build.ensure_fmu`: a sweep's worker checks them once, not for every run.
    """
    if plant not in PLANT_FMUS:
        raise UserError(f"plant FMU {plant!r}: choose {' or '.join(PLANT_FMUS)}")
    system = System(step=step)

    def fmu(name: str) -> Path:
        return fmus[name] if fmus and name in fmus else ensure_fmu(name, fmu_dir)

    plant_start = {**params.as_dict(), **(initial_state or {})}
    system.add("plant", fmu(plant), plant_start)
    supervisor = dict(supervisor or {})
    swing_up = bool(supervisor.get("swing_up", False))
    controller_start = {"Lp": params.Lp, "h": step, **controller_parameters}
    if swing_up and controller_fmu is None:
        controller_start["wrap_angle"] = True  # the pendulum may turn over while it swings up
    controller = system.add("controller", controller_fmu or fmu("Controller"), controller_start)
    if swing_up:
        supervisor.setdefault("pendulum_frequency", hanging_frequency(params))
    system.add("supervisor", fmu("Supervisor"), supervisor)
    has = _inputs_of(controller.fmu) if controller_fmu is not None else None
    for source, target in CONNECTIONS:
        if has is not None and target in MODE_INPUTS and target.partition(".")[2] not in has:
            if supervisor.get("recentre") or swing_up:
                raise UserError(f"controller FMU {controller.fmu.name} has no input {target.partition('.')[2]!r}: "
                                "re-centring and swing-up need a controller with inputs r and engaged")
            continue
        system.connect(source, target, delay=delay if target == VOLTAGE_INPUT else 0)
    return system


def hanging_frequency(params: PlantParameters) -> float:
    """Small-swing frequency (rad/s) of the hanging pendulum about its pivot: the swing-up's energy scale.

    Examples
    --------
    >>> round(hanging_frequency(PlantParameters.preset()), 2)
    4.75
    """
    return float(np.sqrt(params.Mp * params.g * params.lp / (params.Ip + params.Mp * params.lp**2)))


def _inputs_of(fmu: Path) -> set[str]:
    from fmpy import read_model_description

    return {v.name for v in read_model_description(str(fmu)).modelVariables if v.causality == "input"}


def collect_columns(log: Mapping[str, np.ndarray], params: PlantParameters) -> dict[str, np.ndarray]:
    """The recorded signals under the SPEC's column names, plus ``tip`` and the supervisor's ``trip_reason``
    (its codes: :data:`pendulab.fmu.models.supervisor.config.TRIP_REASONS`); ``_safety_cut_time`` aside."""
    columns = {"t": np.asarray(log["time"], dtype=float)}
    for path, name in RECORDED.items():
        columns[name] = np.asarray(log[path], dtype=float)
    columns["tip"] = params.Lp * columns["alpha"]
    trip_times = columns.pop("trip_time")
    reasons = columns["trip_reason"]
    tripped = np.flatnonzero(reasons > 0)
    columns["_safety_cut_time"] = float(trip_times[tripped[0]]) if tripped.size else None  # type: ignore[assignment]
    order = ("t", "x", "xdot", "alpha", "alpha_measured", "tip", "voltage_command", "voltage", "supervisor_state", "trip_reason",
             "_safety_cut_time")
    return {k: columns[k] for k in order}


def describe_controller(controller: Any) -> str:
    describe = getattr(controller, "describe", None)
    return describe() if callable(describe) else str(controller)
