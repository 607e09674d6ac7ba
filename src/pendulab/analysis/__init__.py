"""What comes out of a run: metrics, result files, plots and the rig animation (SPEC §7).

- :mod:`pendulab.analysis.metrics` -- :func:`compute_metrics` (``metrics.json``'s numbers);
- :mod:`pendulab.analysis.results` -- :data:`COLUMNS`, :func:`write_results` (``run.mat``,
  ``run.csv``, ``metrics.json``), :func:`read_run`, :class:`RunLog` (streamed CSV log);
- :mod:`pendulab.analysis.plots` -- :func:`plot_run`, :func:`plot_root_locus` (PNG, off-screen);
- :mod:`pendulab.analysis.animation` -- :func:`animate_run` (GIF of the rig).

The names below are imported on first use, as in :mod:`pendulab.calibration`: ``results`` imports
scipy.io (about 0.2 s), which a process that only simulates and measures (a sweep's worker) never
needs. The plotting modules import matplotlib; import them directly.

Examples
--------
>>> from pendulab.analysis import METRIC_KEYS
>>> METRIC_KEYS[0]
'natural_frequency_rad_s'
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "METRIC_KEYS": "metrics",
    "compute_metrics": "metrics",
    "COLUMNS": "results",
    "RunLog": "results",
    "read_run": "results",
    "write_results": "results",
}

__all__ = sorted(_EXPORTS, key=str.casefold)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
