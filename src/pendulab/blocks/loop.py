"""Run a controller block (a Python block FMU) in the lab's loop, in place of the generic Controller.

The block takes the place of ``controller`` in :func:`pendulab.cosim.pendulum.pendulum_system`:
it gets ``alpha_measured`` and must output ``V_command`` and have the parameters ``Lp`` and ``h``
(the system sets them). Every other input named like a plant output (``x_measured``, ``x``,
``xdot``, ``alpha``, ``alphadot``, ...) is connected from the plant as well.

Examples
--------
>>> from pendulab.blocks.lqr import build_lqr_controller
>>> from pendulab.blocks.loop import simulate_block_controller
>>> result = simulate_block_controller(build_lqr_controller("fmus/"))     # doctest: +SKIP
>>> result.metrics["stable"]                                              # doctest: +SKIP
True
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pendulab.errors import UserError

#: Plant outputs a controller block may take as inputs (connected by name).
PLANT_SIGNALS = ("x", "xdot", "alpha", "alphadot", "alpha_measured", "x_measured", "V_applied", "F_friction")
#: What the loop needs of a controller block.
REQUIRED_VARIABLES = {"alpha_measured": "input", "V_command": "output", "Lp": "parameter", "h": "parameter"}


def block_controller_system(
    fmu: str | Path,
    params: Any = None,
    *,
    step: float = 1e-3,
    supervisor: Mapping[str, Any] | None = None,
    controller_parameters: Mapping[str, Any] | None = None,
    fmu_dir: Path | None = None,
):
    """The three-component loop with the block FMU as controller; plant signals wired by name."""
    from fmpy import read_model_description

    from pendulab.cosim.pendulum import CONNECTIONS, pendulum_system
    from pendulab.model.parameters import PlantParameters

    fmu = Path(fmu)
    if not fmu.is_file():
        raise UserError(f"controller FMU {fmu} does not exist; build it with pendulab.blocks.build_block")
    description = read_model_description(str(fmu))
    causality = {v.name: v.causality for v in description.modelVariables}
    missing = [f"the {kind} {name!r}" for name, kind in REQUIRED_VARIABLES.items() if causality.get(name) != kind]
    if missing:
        raise UserError(f"{fmu.name} cannot be the loop's controller: it lacks {', '.join(missing)}")
    params = params or PlantParameters.preset()
    system = pendulum_system(
        params, dict(controller_parameters or {}), step=step, supervisor=supervisor, fmu_dir=fmu_dir, controller_fmu=fmu
    )
    wired = {target for _, target in CONNECTIONS}
    for name in PLANT_SIGNALS:
        if causality.get(name) == "input" and f"controller.{name}" not in wired:
            system.connect(f"plant.{name}", f"controller.{name}")
    return system


def simulate_block_controller(
    fmu: str | Path,
    params: Any = None,
    *,
    stop_time: float = 5.0,
    step: float = 1e-3,
    supervisor: Mapping[str, Any] | None = None,
    controller_parameters: Mapping[str, Any] | None = None,
    record: Sequence[str] = (),
    fmu_dir: Path | None = None,
):
    """Simulate the poke run with a block controller; like :func:`pendulab.cosim.pendulum.simulate_poke`.

    Parameters
    ----------
    record : sequence of str
        Extra signals (``"controller.xdot_estimate"``) to return in ``result.columns`` under their
        full names.

    Returns
    -------
    pendulab.cosim.pendulum.SimulationResult
    """
    from pendulab import __version__
    from pendulab.analysis.metrics import compute_metrics
    from pendulab.blocks.base import block_error
    from pendulab.cosim.master import Master, SimulationError
    from pendulab.cosim.pendulum import RECORDED, SimulationResult, collect_columns
    from pendulab.model.parameters import PlantParameters

    params = params or PlantParameters.preset()
    system = block_controller_system(
        fmu, params, step=step, supervisor=supervisor, controller_parameters=controller_parameters, fmu_dir=fmu_dir
    )
    with Master(system) as master:
        try:
            log = master.run(stop_time, [*RECORDED, *record])
        except SimulationError as exc:
            detail = block_error("controller")
            if detail:
                raise SimulationError(f"{exc}: {detail}") from exc
            raise
    columns = collect_columns(log, params)
    safety_cut = columns.pop("_safety_cut_time")
    metrics = compute_metrics(
        columns["t"], columns["alpha"], poke_start=params.poke_start, q_alpha=params.q_alpha,
        xdot=columns["xdot"], safety_cut_time=safety_cut,
    )
    for name in record:
        columns[name] = log[name]
    meta = {
        "controller": f"Python block {Path(fmu).name}",
        "step": step,
        "parameters": params.as_dict(),
        "version": __version__,
        "safety_cut_time": safety_cut,
    }
    return SimulationResult(columns, metrics, meta)
