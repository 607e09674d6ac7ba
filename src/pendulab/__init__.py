"""pendulab: the cart-and-pendulum control lab as standard FMI components.

The plant (one CasADi model, compiled into a native FMU), the student's controller and the safety
supervisor are each an FMU, wired by a co-simulation master on fmpy.

The names below are imported on first use, so ``import pendulab`` stays light:

- a run: :func:`simulate` a :class:`RunSpec` (sections :class:`Plant`, :class:`ControllerSpec`,
  :class:`Poke`, :class:`Timing`, :class:`Quantization`, :class:`Supervisor`) into a
  :class:`SimulationResult`;
- the controller: :class:`Controller`, :func:`zpk`, :func:`pid`, :func:`demo_controller`;
- the plant: :class:`PlantParameters`, :func:`tf`, :func:`linearize`;
- calibration: :func:`fit`, :func:`load_calibration`, :func:`read_log`; runs side by side: :func:`compare`;
- blocks of your own: :class:`Block`, :class:`Var`, :func:`build_block`.

Examples
--------
>>> import pendulab
>>> spec = pendulab.RunSpec(pendulab.demo_controller(), poke=pendulab.Poke(220.0), timing=pendulab.Timing(stop_time=2.0))
>>> result = pendulab.simulate(spec)
>>> result.metrics["stable"], result.metrics["safety_cut_time_s"]
(True, None)
>>> [round(float(c), 3) for c in pendulab.tf().num[0][0]]
[5.247, 0.0]
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

#: Public name -> (module, name there). Imported on first use.
_EXPORTS = {
    # a run
    "simulate": ("pendulab.simulation", "simulate"),
    "SimulationResult": ("pendulab.simulation", "SimulationResult"),
    "RunSpec": ("pendulab.spec", "RunSpec"),
    "Plant": ("pendulab.spec", "Plant"),
    "ControllerSpec": ("pendulab.spec", "ControllerSpec"),
    "Poke": ("pendulab.spec", "Poke"),
    "Timing": ("pendulab.spec", "Timing"),
    "Quantization": ("pendulab.spec", "Quantization"),
    "Supervisor": ("pendulab.spec", "Supervisor"),
    # the controller
    "Controller": ("pendulab.control.controller", "Controller"),
    "zpk": ("pendulab.control.controller", "zpk"),
    "pid": ("pendulab.control.controller", "pid"),
    "demo_controller": ("pendulab.control.controller", "demo_controller"),
    # the plant
    "PlantParameters": ("pendulab.model.parameters", "PlantParameters"),
    "tf": ("pendulab.model.linear", "tf"),
    "linearize": ("pendulab.model.linear", "linearize"),
    # calibration and logs
    "fit": ("pendulab.calibration.fit", "fit_parameters"),
    "load_calibration": ("pendulab.calibration.files", "load_calibration"),
    "read_log": ("pendulab.calibration.logs", "read_log"),
    # runs side by side
    "compare": ("pendulab.analysis.compare", "compare_runs"),
    # blocks of your own
    "Block": ("pendulab.blocks.base", "Block"),
    "Var": ("pendulab.blocks.base", "Var"),
    "build_block": ("pendulab.blocks.build", "build_block"),
    "UserError": ("pendulab.errors", "UserError"),
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    target = _EXPORTS.get(name)
    if target is None:
        try:  # subpackages as attributes (pendulab.control), as after 'import pendulab.control'
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module, attribute = target
    value = getattr(importlib.import_module(module), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
