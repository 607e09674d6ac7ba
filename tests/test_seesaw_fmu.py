"""Seesaw.fmu against the CasADi model it is generated from, and in an independent FMI engine (issue 20,
must-show 3: the Co-Simulation part)."""

from __future__ import annotations

import math
from pathlib import Path

import fmi_harness
import numpy as np
import pytest
from fmi_harness import VARARGS_AS_FIXED, Slave, capturing_callbacks

from pendulab.model.seesaw import STATES, SeesawModel, SeesawParameters

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


def test_the_fmi3_seesaw_equals_the_fmi2_one() -> None:
    from fmpy import simulate_fmu

    from pendulab.fmu.build import ensure_fmu

    n = 1200
    V = voltage(n)
    signal = np.array([(k * 1e-3, v) for k, v in enumerate(V)], dtype=[("time", float), ("V", float)])
    runs = [
        simulate_fmu(str(ensure_fmu(name)), fmi_type="CoSimulation", stop_time=n * 1e-3, step_size=1e-3, output_interval=1e-3,
                     start_values={"theta": 0.01}, input=signal, output=["x", "theta", "theta_measured"])
        for name in ("Seesaw", "Seesaw3")
    ]
    assert np.ptp(runs[0]["theta"]) > 0.05
    for name in ("x", "theta", "theta_measured"):
        np.testing.assert_array_equal(runs[1][name], runs[0][name])
