"""Closed-loop runs of the three FMUs (issue 3, must-show 4; SPEC §5, §7): the demo controller keeps
both pendulums up through the default poke, an unstable controller ends at a recorded safety cut, and
``run.mat`` from ``pendulab simulate`` holds every column for MATLAB.

(The metrics of a synthetic damped sine are tested in tests/test_metrics.py.)
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from pendulab.analysis.results import COLUMNS, read_run
from pendulab.control.controller import demo_controller, unstable_example
from pendulab.fmu.models.supervisor.config import ALPHA_MAX_DEFAULT, RUNNING, TRIP_ANGLE, TRIPPED, X_MAX_DEFAULT
from pendulab.model.parameters import PlantParameters
from pendulab.simulation import simulate
from pendulab.spec import Plant, RunSpec, Timing

METRIC_KEYS = {
    "natural_frequency_rad_s",
    "peak_time_s",
    "overshoot_percent",
    "settling_time_s",
    "final_value_rad",
    "cart_speed_change_m_s",
    "safety_cut_time_s",
    "stable",
    "limit_cycle_amplitude_rad",  # SPEC §7: the friction and quantization limit cycle (else null)
    "limit_cycle_frequency_rad_s",
}


@pytest.fixture(scope="module", params=["long", "short"])
def demo_run(request, loop_fmus):
    params = PlantParameters.preset(request.param)  # the default poke: 50 rad/s^2, 5 ms, at 1 s
    return params, simulate(RunSpec(demo_controller(request.param), plant=Plant(pendulum=request.param)))


def test_demo_keeps_the_pendulum_up_through_the_default_poke(demo_run):
    params, result = demo_run
    c, m = result.columns, result.metrics
    assert (params.poke_magnitude, params.poke_duration, params.poke_start) == (50.0, 0.005, 1.0)
    assert m["safety_cut_time_s"] is None and m["stable"] is True
    assert np.all(c["supervisor_state"] == RUNNING), "never tripped, never paused"
    before, after = c["t"] < params.poke_start, c["t"] >= params.poke_start
    # Upright and still before the poke (the encoder reads 0), a real swing after it, small throughout.
    assert np.all(c["alpha_measured"][before] == 0)
    swing = np.max(np.abs(c["alpha"][after]))
    assert math.radians(0.3) < swing < math.radians(3.0)
    assert np.max(np.abs(c["x"])) < 0.5 * X_MAX_DEFAULT
    assert np.max(np.abs(c["voltage"])) < 5.0
    # In the last second the pendulum is back near upright (a friction limit cycle of about 1 deg is allowed).
    last = c["t"] > c["t"][-1] - 1.0
    assert np.max(np.abs(c["alpha"][last])) < math.radians(1.5)
    assert m["final_value_rad"] is not None and abs(m["final_value_rad"]) < math.radians(1.5)


def test_the_loop_is_wired_as_the_spec_says(demo_run):
    """voltage = the supervisor's gate of the command (clamped to 10 V while running); tip = Lp*alpha."""
    params, result = demo_run
    c = result.columns
    np.testing.assert_array_equal(c["voltage"], np.clip(c["voltage_command"], -10, 10))
    np.testing.assert_array_equal(c["tip"], params.Lp * c["alpha"])
    # The encoder quantizes the angle in steps of q_alpha.
    np.testing.assert_allclose(c["alpha_measured"] / params.q_alpha, np.round(c["alpha_measured"] / params.q_alpha), atol=1e-9)
    assert np.max(np.abs(c["alpha_measured"] - c["alpha"])) <= params.q_alpha / 2 + 1e-12


@pytest.fixture(scope="module")
def unstable_run(loop_fmus):
    return PlantParameters.preset(), simulate(RunSpec(unstable_example(), timing=Timing(stop_time=3.0)))


def test_unstable_controller_ends_at_a_recorded_safety_cut(unstable_run):
    params, result = unstable_run
    c, m = result.columns, result.metrics
    cut = m["safety_cut_time_s"]
    assert cut is not None and m["stable"] is False
    assert params.poke_start < cut < params.poke_start + 0.5
    # The cut happens at the first communication point where the measured angle is past 15 deg.
    beyond = np.flatnonzero(np.abs(c["alpha_measured"]) > ALPHA_MAX_DEFAULT)
    k = beyond[0]
    assert c["t"][k] == pytest.approx(cut, abs=1e-12)
    # The supervisor_state column shows the trip from that point on, latched.
    state = c["supervisor_state"]
    assert np.all(state[:k] == RUNNING) and np.all(state[k:] == TRIPPED)
    # The voltage is 0 from the cut on, although the controller still commands a large voltage.
    assert np.all(c["voltage"][k:] == 0)
    assert np.all(c["voltage"][:k] == np.clip(c["voltage_command"][:k], -10, 10))
    assert np.min(np.abs(c["voltage_command"][k:])) > 1.0
    # The pendulum falls on without the motor; the metrics describe no oscillation.
    assert abs(c["alpha"][-1]) > ALPHA_MAX_DEFAULT
    assert m["natural_frequency_rad_s"] is None and m["final_value_rad"] is None


def test_trip_reason_and_time_are_logged_by_the_supervisor(loop_fmus):
    from pendulab.control.realization import discretize
    from pendulab.cosim.master import Master
    from pendulab.cosim.pendulum import pendulum_system

    params = PlantParameters.preset()
    system = pendulum_system(params, discretize(unstable_example()).to_parameters())
    with Master(system) as master:
        log = master.run(2.0, ["supervisor.trip_reason", "supervisor.trip_time", "supervisor.state"])
    k = np.flatnonzero(log["supervisor.state"] == TRIPPED)[0]
    assert np.all(log["supervisor.trip_reason"][:k] == 0) and np.all(log["supervisor.trip_reason"][k:] == TRIP_ANGLE)
    assert np.all(log["supervisor.trip_time"][:k] == -1) and np.all(log["supervisor.trip_time"][k:] == log["time"][k])


# ---------------------------------------------------------------- run.mat from the command line
@pytest.fixture(scope="module")
def cli_run(tmp_path_factory, loop_fmus) -> Path:
    out = tmp_path_factory.mktemp("cli") / "run"
    result = subprocess.run(
        [sys.executable, "-m", "pendulab", "simulate", "--demo", "--pendulum", "short", "--poke", "220,0.005,0.5",
         "--stop-time", "2", "--out", str(out)],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("BALANCED for 2 s")
    return out


def test_run_mat_loads_with_scipy_and_holds_every_column(cli_run):
    mat = scipy.io.loadmat(cli_run / "run.mat")
    n = 2001  # 0 .. 2 s at 1 ms
    for name in ("t", "x", "xdot", "alpha", "alpha_measured", "tip", "voltage_command", "voltage", "supervisor_state"):
        assert name in mat, name
        assert mat[name].shape == (n, 1), f"{name} is a column vector"
        assert mat[name].dtype == np.float64 and np.all(np.isfinite(mat[name]))
    assert set(COLUMNS) <= set(mat)
    np.testing.assert_allclose(mat["t"][:, 0], np.arange(n) * 1e-3, atol=1e-12)
    np.testing.assert_allclose(mat["tip"], PlantParameters.preset("short").Lp * mat["alpha"], rtol=1e-15)
    assert np.ptp(mat["alpha"]) > 0.01, "the 220 rad/s^2 poke moved the pendulum"
    assert np.all(mat["supervisor_state"] == RUNNING)


def test_run_mat_meta_struct(cli_run):
    meta = scipy.io.loadmat(cli_run / "run.mat", squeeze_me=True, struct_as_record=False)["meta"]
    for field in ("controller", "parameters", "calibration", "pendulum", "version"):
        assert hasattr(meta, field), field
    assert meta.pendulum == "short"
    assert meta.controller == demo_controller("short").describe()
    assert float(meta.parameters.Lp) == pytest.approx(PlantParameters.preset("short").Lp)
    assert float(meta.parameters.poke_magnitude) == 220.0 and float(meta.parameters.poke_start) == 0.5
    from pendulab import __version__

    assert meta.version == __version__


def test_run_csv_and_metrics_match_run_mat(cli_run):
    mat = scipy.io.loadmat(cli_run / "run.mat")
    columns, _ = read_run(cli_run / "run.csv")
    for name in COLUMNS:
        np.testing.assert_allclose(columns[name], mat[name][:, 0], rtol=1e-12, atol=1e-15, err_msg=name)
    metrics = json.loads((cli_run / "metrics.json").read_text())
    # SPEC §7's keys, and the reasons for the ones not reported, the cut's reason and the verdict (issue 24).
    assert set(metrics) == METRIC_KEYS | {"not_reported", "safety_cut_reason", "verdict"}
    assert metrics["verdict"]["outcome"] == "balanced" and metrics["safety_cut_reason"] is None
    np.testing.assert_array_equal(columns["trip_reason"], 0.0)  # the supervisor's reason column: no trip
    assert metrics["stable"] is True and metrics["safety_cut_time_s"] is None
