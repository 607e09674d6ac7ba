"""pendulab: the cart-and-pendulum control lab as standard FMI components.

The plant (one CasADi model, compiled into a native FMU), the student's controller and the safety
supervisor are each an FMU, wired by a co-simulation master on fmpy.

The names below are imported on first use, so ``import pendulab`` stays light.

Examples
--------
>>> import pendulab
>>> spec = pendulab.RunSpec(pendulab.control.demo_controller(), timing=pendulab.Timing(stop_time=2.0))
>>> spec.timing.stop_time
2.0
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

#: Public name -> the module that defines it.
_EXPORTS = {
    "simulate": "pendulab.simulation",
    "SimulationResult": "pendulab.simulation",
    "RunSpec": "pendulab.spec",
    "Plant": "pendulab.spec",
    "ControllerSpec": "pendulab.spec",
    "Poke": "pendulab.spec",
    "Timing": "pendulab.spec",
    "Quantization": "pendulab.spec",
    "Supervisor": "pendulab.spec",
    "UserError": "pendulab.errors",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        try:  # subpackages as attributes (pendulab.control), as after 'import pendulab.control'
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
