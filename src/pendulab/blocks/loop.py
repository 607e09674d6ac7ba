"""Run a controller block (a Python block FMU) in the lab's loop, in place of the generic Controller.

The block takes the place of ``controller`` in :func:`pendulab.cosim.pendulum.pendulum_system`
(:func:`pendulab.simulate` of a spec whose ``controller.fmu`` is the block):
it gets ``alpha_measured`` and must output ``V_command`` and have the parameters ``Lp`` and ``h``
(the system sets them). Every other input named like a plant output (``x_measured``, ``x``,
``xdot``, ``alpha``, ``alphadot``, ...) is connected from the plant as well.

Examples
--------
>>> import pendulab, tempfile
>>> from pendulab.blocks.lqr import build_lqr_controller
>>> fmu = build_lqr_controller(tempfile.mkdtemp())
>>> result = pendulab.simulate(pendulab.RunSpec(pendulab.ControllerSpec(fmu=str(fmu)), timing=pendulab.Timing(stop_time=2.0)))
>>> result.metrics["safety_cut_time_s"] is None
True
"""

from __future__ import annotations

from collections.abc import Mapping
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
    delay: int = 0,
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
        params, dict(controller_parameters or {}), step=step, supervisor=supervisor, fmu_dir=fmu_dir, controller_fmu=fmu,
        delay=delay,
    )
    wired = {target for _, target in CONNECTIONS}
    for name in PLANT_SIGNALS:
        if causality.get(name) == "input" and f"controller.{name}" not in wired:
            system.connect(f"plant.{name}", f"controller.{name}")
    return system
