"""Least-squares refit (must-show 2): synthetic logs with known parameters, noise and quantization."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pendulab import exact
from pendulab.calibration.fit import START_DIGITS, fit_parameters, plot_fit, ramp_start
from pendulab.calibration.logs import RampLog
from pendulab.calibration.synthetic import TEST_RIG
from pendulab.errors import CalibrationError, FitRejected
from pendulab.model.parameters import PlantParameters

TRUE = TEST_RIG


@pytest.fixture(scope="module")
def result(ramp_test_fit):
    log, _, fitted = ramp_test_fit  # conftest: the calibrate ramp test's log, fitted from the lab defaults
    counts = log.x / TRUE.q_x
    assert np.allclose(counts, np.round(counts))  # quantized to the encoder step
    return log, fitted


def test_fit_recovers_Beq_force_gain_and_F1(result):
    log, result = result
    assert result.forward_ok
    assert abs(result.values["Beq"] / TRUE.Beq - 1) < 0.05
    assert abs(result.values["force_gain"] / TRUE.force_gain - 1) < 0.05
    assert abs(result.values["F1"] / TRUE.F1 - 1) < 0.10
    # The start was far away: this is a real fit, not the defaults left alone.
    assert result.initial["Beq"] == 4.3 and result.initial["force_gain"] == 1.0
    # The friction starts where the one start rule puts it (the ramp extraction), as 'pendulab fit' does.
    start, _ = ramp_start([log], PlantParameters.preset("none"))
    assert result.initial["F1"] == exact.significant(start.F1, START_DIGITS) != 1.5  # the extraction's, rounded (the same on any CPU)


def test_fit_reports_what_the_log_determines_its_uncertainty_and_residual(result):
    _, result = result
    for name in result.names:
        if result.determination[name] == "determined":
            assert 0 < result.uncertainty[name] < abs(result.values[name])
            # Never below the profile's finest offset (0.3 %), under which the replay cost is a staircase:
            # here the force gain's own interpolated half-width was 0.25 %.
            assert result.uncertainty[name] >= 0.003 * abs(result.values[name])
        else:  # bounded or not identified: no uncertainty, a range instead
            assert result.uncertainty[name] == math.inf and result.allowed[name] != (0.0, math.inf)
            assert result.determination[name] == "bounded" or result.values[name] == result.initial[name]
    # A ramp test shows the drive, the drag and the breakaway.
    assert all(result.determination[n] == "determined" for n in ("Beq", "force_gain", "F1"))
    assert 1e-6 < result.residual_rms < 1e-4  # about the noise (10 um) and the encoder step
    assert result.params.Beq == result.values["Beq"]
    cal = result.to_calibration(rig="test")
    assert cal.Beq == result.values["Beq"] and cal.force_gain == result.values["force_gain"]
    assert cal.friction[0] == result.values["F1"]
    assert cal.metadata["determination"] == result.determination
    assert "Beq" in result.summary() and "determined" in result.summary()


def test_plot_of_measured_against_refitted_motion(result, tmp_path):
    _, result = result
    path = plot_fit(result, tmp_path / "fit.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    curve = result.curves[0]
    assert np.sqrt(np.mean((curve.x_fitted - curve.x_measured) ** 2)) < 1e-4


def test_fit_errors_are_user_errors():
    t = np.arange(3000) * 1e-3
    still = RampLog(t, np.where(t > 1, 0.3, 0.0), np.zeros_like(t), source="still.csv")
    with pytest.raises(FitRejected, match="never moves.*determines nothing; record slow voltage ramps"):
        fit_parameters([still])
    short = RampLog(t[:15], np.linspace(0, 1, 15), np.linspace(0, 1e-3, 15), source="short.csv")
    with pytest.raises(CalibrationError, match="too short"):
        fit_parameters([short])
    moving = RampLog(t, np.minimum(t, 1.0), t * 0.1)
    with pytest.raises(CalibrationError, match="cannot fit 'Mp'"):
        fit_parameters([moving], fit=("Mp",))
    with pytest.raises(CalibrationError, match="no alpha column"):
        fit_parameters([moving], PlantParameters.preset("long"))


def test_a_fit_of_one_parameter_runs_no_evolution_strategy(monkeypatch):
    """CMA-ES is a search over several parameters: a fit of one (the polish's scans search it) skips every run of it, a fit
    of two runs it. (A whole fit of one parameter would compile a replay of its own; tests/test_wheel.py fits one.)"""
    from types import SimpleNamespace

    from pendulab.calibration import _polish  # private: the stage's guard, without a replay
    from pendulab.calibration import fit as fit_module  # private: the stage's guard, without a replay

    runs = []
    # CMA-ES finds nothing lower, so nothing after it runs (no polish, no replay: setup has no space); every cost is above the target
    monkeypatch.setattr(_polish, "evolve", lambda *args, **kwargs: runs.append(args) or (args[2], math.inf))
    monkeypatch.setattr(fit_module, "_cost_of", lambda *args: 0.0)
    polished = _polish.Polished(np.ones(2), 1.0, 1.0, 0, 0)
    whole: list = []  # what the polish and CMA-ES replay: the same (a short log's whole)
    answer = fit_module._Answer(SimpleNamespace(theta=np.ones(2), whole=[]), polished, whole, whole, rms=1.0)  # far off: every stage would run
    for names, expected in ((("force_gain",), 0), (("Beq", "force_gain"), 1)):
        setup = SimpleNamespace(names=names, with_pendulum=False, step=1e-5, space=None, theta0=np.ones(len(names)), progress=print,
                                search_pieces=[])
        runs.clear()
        assert fit_module._evolved(setup, answer, "answer") is answer
        assert (len(runs) > 0) == bool(expected), (names, len(runs))


def test_a_synthetic_log_made_again_is_the_same_log_and_its_own():
    """The runs behind synthetic logs are cached: the same log to the bit, with and without voltage noise, and arrays of its own."""
    from pendulab.calibration.synthetic import synthetic_log

    first = synthetic_log("chirp", TEST_RIG, duration=2.0, voltage_noise=0.01)
    first.x[:] = 0.0
    first.V[:] = 0.0
    again, clean = synthetic_log("chirp", TEST_RIG, duration=2.0, voltage_noise=0.01), synthetic_log("chirp", TEST_RIG, duration=2.0, voltage_noise=0.0)
    assert np.ptp(again.x) > 0.01 and np.array_equal(again.x, clean.x)  # the same run; the zeros written into the first stayed there
    assert 0.005 < np.std(again.V - clean.V) < 0.015  # the noise drawn anew on the cached voltage
