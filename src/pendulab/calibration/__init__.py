"""Calibration (SPEC §8): ramp test, friction extraction, least-squares refit, calibration files.

- :mod:`~pendulab.calibration.rig`: the :class:`Rig` interface and the :class:`VirtualRig`;
- :mod:`~pendulab.calibration.ramp`: :func:`run_ramp_test`;
- :mod:`~pendulab.calibration.extract`: :func:`extract_friction`, :func:`mass_ratio`;
- :mod:`~pendulab.calibration.fit`: :func:`fit_parameters`, :func:`plot_fit`;
- :mod:`~pendulab.calibration.files`: :class:`Calibration`, :func:`load_calibration`,
  :func:`save_calibration`, :func:`default_calibration`;
- :mod:`~pendulab.calibration.logs`: :class:`RampLog`, :func:`read_log`, :func:`write_log`.

The submodules import CasADi, fmpy and scipy, loaded lazily here, so ``from pendulab.calibration.files import load_calibration`` stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

from pendulab.errors import CalibrationError as CalibrationError  # light: no lazy import needed

#: The public names, by the submodule that defines them (the list above).
_BY_MODULE = {
    "files": ("Calibration", "DEFAULT_CALIBRATION_PATH", "default_calibration", "load_calibration", "save_calibration"),
    "logs": ("RampLog", "read_log", "write_log"),
    "rig": ("Rig", "VirtualRig"),
    "ramp": ("RampSettings", "run_ramp_test"),
    "extract": ("FrictionEstimate", "extract_friction", "mass_ratio"),
    "fit": ("FitResult", "fit_parameters", "plot_fit"),
}
_EXPORTS = {name: module for module, names in _BY_MODULE.items() for name in names}

__all__ = sorted([*_EXPORTS, "CalibrationError"])


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
