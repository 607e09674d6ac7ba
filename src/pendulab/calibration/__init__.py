"""Calibration (SPEC §8): ramp test, friction extraction, least-squares refit, calibration files.

- :mod:`~pendulab.calibration.rig`: the :class:`Rig` interface and the :class:`VirtualRig`;
- :mod:`~pendulab.calibration.ramp`: :func:`run_ramp_test`;
- :mod:`~pendulab.calibration.extract`: :func:`extract_friction`, :func:`mass_ratio`;
- :mod:`~pendulab.calibration.fit`: :func:`fit_parameters`, :func:`plot_fit`;
- :mod:`~pendulab.calibration.files`: :class:`Calibration`, :func:`load_calibration`,
  :func:`save_calibration`, :func:`default_calibration`;
- :mod:`~pendulab.calibration.logs`: :class:`RampLog`, :func:`read_log`, :func:`write_log`.

The submodules import CasADi, fmpy and scipy; this package imports them lazily so that
``from pendulab.calibration.files import load_calibration`` stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

from pendulab.errors import CalibrationError as CalibrationError  # light: no lazy import needed

_EXPORTS = {
    "Calibration": "files",
    "DEFAULT_CALIBRATION_PATH": "files",
    "default_calibration": "files",
    "load_calibration": "files",
    "save_calibration": "files",
    "RampLog": "logs",
    "read_log": "logs",
    "write_log": "logs",
    "Rig": "rig",
    "VirtualRig": "rig",
    "RampSettings": "ramp",
    "run_ramp_test": "ramp",
    "FrictionEstimate": "extract",
    "extract_friction": "extract",
    "mass_ratio": "extract",
    "FitResult": "fit",
    "fit_parameters": "fit",
    "plot_fit": "fit",
}

__all__ = sorted([*_EXPORTS, "CalibrationError"])


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
