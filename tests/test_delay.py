"""The rig's transport delay in simulation (``simulate --delay N``, SPEC §9): the plant gets the
voltage computed N control periods earlier, identically in the native runner and the Python loop."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from pendulab.cli.main import main
from pendulab.control.controller import demo_controller
from pendulab.control.realization import discretize
from pendulab.cosim.master import Master
from pendulab.cosim.pendulum import RECORDED, pendulum_system
from pendulab.errors import UserError
from pendulab.model.parameters import PlantParameters
from pendulab.simulation import simulate
from pendulab.spec import Poke, Quantization, RunSpec, Timing

H = 1e-3


def _run(delay: int, native: bool) -> dict[str, np.ndarray]:
    params = PlantParameters.preset().with_values(poke_start=0.2, poke_magnitude=220.0)
    system = pendulum_system(params, discretize(demo_controller(), h=H).to_parameters(), step=H, delay=delay)
    with Master(system, native=native) as master:
        return master.run(1.0, [*RECORDED, "plant.V", "supervisor.V"])


@pytest.mark.parametrize("delay", [1, 2, 3])
def test_plant_input_is_the_supervisor_output_n_steps_earlier(delay):
    log = _run(delay, native=True)
    sup, plant = log["supervisor.V"], log["plant.V"]
    assert np.all(plant[:delay] == 0.0)  # before any output: the supervisor's start value, 0 V
    assert np.array_equal(plant[delay:], sup[:-delay])
    assert np.ptp(sup) > 1.0  # the loop really acted (the poke), so the equality says something


@pytest.mark.parametrize("delay", [0, 2])
def test_native_runner_and_python_loop_agree_with_a_delay(delay):
    native, python = _run(delay, True), _run(delay, False)
    for name in native:
        assert np.array_equal(native[name], python[name]), name


def test_delay_changes_the_response_the_way_a_delay_does():
    """More delay: less phase margin, so a larger overshoot after the same poke (a student sees it)."""
    base = RunSpec(demo_controller(), poke=Poke(magnitude=220.0), quantization=Quantization(enabled=False))
    base = base.replace(plant=dataclasses.replace(base.plant, overrides={"F1": 0.0, "F2": 0.0}))
    p = base.parameters()
    peaks = []
    for delay in (0, 3, 6):
        result = simulate(base.replace(timing=Timing(stop_time=2.0, delay=delay)))
        a = result.columns["alpha"][result.columns["t"] >= p.poke_start]
        peaks.append(np.max(np.abs(a)))
        assert result.meta["delay"] == delay
    assert peaks[0] < peaks[1] < peaks[2]


def test_simulate_delay_option(tmp_path, capsys):
    assert main(["simulate", "--demo", "--delay", "2", "--stop-time", "2", "--out", str(tmp_path / "d2")]) == 0
    import scipy.io

    m = scipy.io.loadmat(tmp_path / "d2" / "run.mat", squeeze_me=True, struct_as_record=False)
    v, cmd = m["voltage"], np.clip(m["voltage_command"], -10, 10)
    assert np.array_equal(v[2:], cmd[:-2]) and m["meta"].delay == 2
    for bad in ("-1", "9"):
        assert main(["simulate", "--demo", "--delay", bad, "--out", str(tmp_path / "bad")]) == 2
        assert "--delay" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()


def test_connection_delay_must_be_a_whole_number_of_steps(tmp_path):
    params = PlantParameters.preset()
    with pytest.raises(UserError, match="whole number"):
        pendulum_system(params, discretize(demo_controller(), h=H).to_parameters(), step=H, delay=-1)
    with pytest.raises(UserError, match="whole number"):
        pendulum_system(params, discretize(demo_controller(), h=H).to_parameters(), step=H, delay=1.5)  # type: ignore[arg-type]


def test_ssp_export_refuses_a_delayed_loop(tmp_path):
    from pendulab.cosim.ssp import export_ssp

    params = PlantParameters.preset()
    system = pendulum_system(params, discretize(demo_controller(), h=H).to_parameters(), step=H, delay=1)
    with pytest.raises(UserError, match="transport delay"):
        export_ssp(system, tmp_path / "loop.ssp", stop_time=1.0)
    assert not (tmp_path / "loop.ssp").exists()
