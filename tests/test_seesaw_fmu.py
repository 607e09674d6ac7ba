"""Seesaw.fmu against the CasADi model it is generated from (Co-Simulation, and Model Exchange in fmpy's CVode),
and in an independent FMI engine (issue 20, must-show 3). Under Wine: tests/test_fmu_win64.py."""

from __future__ import annotations

import math
from pathlib import Path

import fmi_harness
import numpy as np
import pytest
from fmi_harness import VARARGS_AS_FIXED, Slave, capturing_callbacks
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from pendulab.model.seesaw import EVENT_INDICATORS, STATES, SeesawModel, SeesawParameters

OUTPUTS = (*STATES, "theta_measured", "x_measured", "V_applied")


def voltage(n: int) -> np.ndarray:
    """Steps and a sine that move the cart both ways, break it away and saturate the amplifier once."""
    t = np.arange(n) * 1e-3
    return np.where(t < 0.3, 2.5, 3.0 * np.sin(2 * np.pi * 1.3 * t)) + np.where((t > 0.9) & (t < 0.95), 12.0, 0.0)


def run_fmu(path: Path, V: np.ndarray, start: dict[str, float]) -> np.ndarray:
    return fmi_harness.run_cs(path, OUTPUTS, {"V": V}, start=start)


def test_co_simulation_equals_the_casadi_model(seesaw_fmu: Path) -> None:
    n = 1500
    V = voltage(n)
    start = {"x": 0.02, "theta": 0.01, "tap_start": 0.5}
    fmu = run_fmu(seesaw_fmu, V, start)
    params = SeesawParameters(tap_start=0.5)
    reference = SeesawModel().simulate(params, V, x0=(0.02, 0.0, 0.01, 0.0))
    assert np.ptp(fmu[:, 2]) > 0.05, "a real tilt, not a resting state"
    assert fmu[:, 2].min() == pytest.approx(-params.theta_stop)  # it reaches the tilt stop
    np.testing.assert_allclose(fmu[:, :4], reference, rtol=1e-9, atol=1e-12)
    # The encoders: the tilt in whole counts of the 4096-line encoder behind its 3:1 gear.
    counts = fmu[:, 4] / params.q_theta
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.max(np.abs(fmu[:, 4] - fmu[:, 2])) <= params.q_theta / 2 + 1e-12
    assert np.max(np.abs(fmu[:, 6])) == pytest.approx(params.V_max)


@pytest.mark.parametrize("name", ["Seesaw", "Seesaw3"])
def test_seesaw_fmus_validate_with_model_exchange_and_co_simulation(name: str, seesaw_fmu: Path, seesaw3_fmu: Path) -> None:
    path = {"Seesaw": seesaw_fmu, "Seesaw3": seesaw3_fmu}[name]
    assert validate_fmu(str(path)) == []
    md = read_model_description(str(path))
    assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier == name
    assert md.numberOfEventIndicators == len(EVENT_INDICATORS) and md.numberOfContinuousStates == len(STATES)


#: Model Exchange's case: the seesaw starts just off its tilt stop with the cart on the raised side; a 6 V sine
#: drives the cart and a 12 V pulse (saturated at V_max) at 1.5 s lifts the seesaw off the stop it fell onto;
#: the cart sticks, slips, slides on the stick/slip surfaces and ends on the track's stop; the tap at 1 s.
ME_STEPS, ME_START = 2500, {"x": -0.1, "theta": -0.2}


def me_voltage() -> np.ndarray:
    t = np.arange(ME_STEPS) * 1e-3
    return 6.0 * np.sin(2 * np.pi * 0.7 * t) + np.where((t > 1.5) & (t < 1.55), 12.0, 0.0)


def run_model_exchange(path: Path, rtol: float, steps: int = ME_STEPS, record_events: bool = False) -> np.ndarray:
    """fmpy's CVode on the FMU, the voltage held per 1 ms sample (a repeated time stamp is an input event, where
    fmpy restarts CVode); with ``record_events``, a row before and after each event too."""
    tk = np.arange(steps) * 1e-3
    V = me_voltage()[:steps]
    signal = np.array(list(zip(np.repeat(tk, 2)[1:], np.repeat(V, 2)[:-1])), dtype=[("time", float), ("V", float)])
    return simulate_fmu(str(path), fmi_type="ModelExchange", solver="CVode", relative_tolerance=rtol, stop_time=steps * 1e-3,
                        start_values=ME_START, input=signal, output=[*STATES, "V_applied"], output_interval=1e-3,
                        record_events=record_events)


def test_model_exchange_in_cvode_equals_the_casadi_model(seesaw_fmu: Path) -> None:
    """The switches frozen between events (friction regime, current branch, track and tilt stops) and located by the
    event indicators: CVode completes (the stick/slip surfaces slide instead of chattering) and follows the CasADi
    model's fixed-step RK4 (the Co-Simulation law) within 1e-5 (measured: 5.0e-6 m, 2.0e-6 rad)."""
    me = run_model_exchange(seesaw_fmu, 1e-8)
    params = SeesawParameters()
    reference = SeesawModel().simulate(params, me_voltage(), x0=(ME_START["x"], 0.0, ME_START["theta"], 0.0))
    assert me["time"][-1] == pytest.approx(ME_STEPS * 1e-3) and len(me) == len(reference)
    theta, x, L = reference[:, 2], reference[:, 0], params.track_half_length
    on_stop = theta == -params.theta_stop
    assert 0.3 < on_stop.mean() < 0.95 and theta.max() > -params.theta_stop + 0.01, "rests on its tilt stop, then lifts off"
    assert np.any(x == L) and np.any(reference[:, 1] == 0.0), "the cart reaches the track's stop and stands still"
    assert np.any(np.abs(me["V_applied"]) == params.V_max), "the amplifier saturates"
    np.testing.assert_allclose(me["x"], x, rtol=0, atol=1e-5)
    np.testing.assert_allclose(me["theta"], theta, rtol=0, atol=1e-5)


def test_ecos_runs_the_seesaw_as_fmpy_does(seesaw_fmu: Path) -> None:
    pytest.importorskip("ecospy")
    V = voltage(800)
    rows = fmi_harness.ecos_run(seesaw_fmu, OUTPUTS, V, {"theta": 0.01})
    np.testing.assert_allclose(np.array(rows), run_fmu(seesaw_fmu, V, {"theta": 0.01}), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("start, words", [({"theta": 0.5}, "abs(theta) <= theta_stop is violated (theta = 0.5, theta_stop = 0.200713)"),
                                          ({"J_sw": -1.0}, "J_sw = -1 is outside its range 0.0001 to 100 kg.m2"),
                                          ({"xdot": math.nan}, "not finite")])
def test_a_start_beyond_the_stops_or_a_bad_parameter_is_refused_with_a_log_line(seesaw_fmu: Path, start: dict[str, float], words: str) -> None:
    from fmpy.fmi1 import FMICallException

    messages: list[str] = []
    with Slave(seesaw_fmu, callbacks=capturing_callbacks(messages), initialize=False) as seesaw:
        seesaw.fmu.setupExperiment(startTime=0.0)
        seesaw.fmu.enterInitializationMode()
        with pytest.raises(FMICallException):  # a value outside its range is refused when set, the rest on leaving
            seesaw.set(start)
            seesaw.fmu.exitInitializationMode()
        if VARARGS_AS_FIXED:
            assert any(words in m for m in messages), messages


def test_the_fmi3_seesaw_equals_the_fmi2_one(seesaw_fmu: Path, seesaw3_fmu: Path) -> None:
    n = 1200
    V = voltage(n)
    signal = np.array([(k * 1e-3, v) for k, v in enumerate(V)], dtype=[("time", float), ("V", float)])
    runs = [
        simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=n * 1e-3, step_size=1e-3, output_interval=1e-3,
                     start_values={"theta": 0.01}, input=signal, output=["x", "theta", "theta_measured"])
        for path in (seesaw_fmu, seesaw3_fmu)
    ]
    assert np.ptp(runs[0]["theta"]) > 0.05
    for name in ("x", "theta", "theta_measured"):
        np.testing.assert_array_equal(runs[1][name], runs[0][name])
    # Model Exchange in CVode: the same events (a row before and after each) and states, bit for bit, to past the
    # tap and the 12 V pulse (FMI 3.0's event indicators are variables of their own).
    me2, me3 = (run_model_exchange(path, 1e-6, steps=1600, record_events=True) for path in (seesaw_fmu, seesaw3_fmu))
    assert len(me3) == len(me2) > 1601 + 1600  # the output points and the events' rows (the input samples' too)
    for name in ("time", *STATES):
        np.testing.assert_array_equal(me3[name], me2[name])
