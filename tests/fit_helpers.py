"""Test helpers: a cart log prepared for the fit's replays as the fit does it, and the fit's search space."""

from __future__ import annotations

import numpy as np

from pendulab.calibration import _polish  # private: the fit's replay objective is what the fit's tests check
from pendulab.calibration.fit import _LOWER, _UPPER, DEFAULT_FIT, _initial_states, _noise_level  # private: the fit's space
from pendulab.calibration.logs import RampLog
from pendulab.model.parameters import PlantParameters
from pendulab.model.plant import PlantModel


def simulate(params: PlantParameters | np.ndarray, V: np.ndarray, step: float, x0=(0.0, 0.0, 0.0, 0.0), t0: float = 0.0) -> np.ndarray:
    """The reference: :meth:`PlantModel.simulate` (a Python loop of the plant's RK4 step in CasADi's virtual machine),
    for parameters or a full parameter vector; the states at ``t0, t0 + step, ...``, ``(n + 1, 4)``."""
    if not isinstance(params, PlantParameters):
        params = PlantParameters(**dict(zip(PlantParameters.names(), map(float, params))))
    return PlantModel().simulate(params, V, step, x0, t0=t0)


def prepared(log: RampLog, step: float) -> tuple[list[_polish.Anchors], _polish.Space]:
    """The log's anchors (state estimates every 10 samples, restarts at its rests; encoder step ``step``) and the
    space of :data:`DEFAULT_FIT`, scaled by the lab's defaults, within the fit's bounds."""
    used = ((len(log) - 1) // 10) * 10 + 1
    sigma = np.array([_noise_level(log.x[:used])])
    anchors = [_polish.anchors(log, used, _initial_states(log, False)[:used:10].T, 10, sigma, step, False)]
    lab = PlantParameters.preset("none")
    scales = np.array([getattr(lab, n) for n in DEFAULT_FIT])
    space = _polish.Space(lab, DEFAULT_FIT, scales, np.array([_LOWER[n] for n in DEFAULT_FIT]) / scales, np.array([_UPPER[n] for n in DEFAULT_FIT]) / scales)
    return anchors, space


def scaled(params: PlantParameters, space: _polish.Space) -> np.ndarray:
    """``params``' fitted values as the search sees them (scaled)."""
    return np.array([getattr(params, n) for n in space.names]) / space.scales
