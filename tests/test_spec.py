"""RunSpec (one validated description of a run) and pendulab.simulate (the one way to run it)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import scipy.io

from pendulab.control import Controller, demo_controller
from pendulab.errors import UserError
from pendulab.model.parameters import PlantParameters
from pendulab.spec import ControllerSpec, Plant, Poke, Quantization, RunSpec, Supervisor, Timing


def a_spec() -> RunSpec:
    return RunSpec(
        Controller.pid(600, 200, 5),
        plant=Plant(pendulum="short", cart="ip01", overrides={"Beq": 1.25}),
        poke=Poke(220.0, 0.005, 0.3),
        timing=Timing(stop_time=1.5, step=2e-3, method="zoh", delay=2),
        quantization=Quantization(q_alpha=2e-3),
        supervisor=Supervisor(alpha_max=0.2, x_max=0.35),
    )


@pytest.mark.parametrize("form", ["dict", "json", "toml"])
def test_a_spec_reads_back_from_each_serialization(form):
    spec = a_spec()
    if form == "dict":
        back = RunSpec.from_dict(json.loads(json.dumps(spec.to_dict())))
    elif form == "json":
        back = RunSpec.from_json(spec.to_json())
    else:
        back = RunSpec.from_toml(spec.to_toml())
    assert back == spec
    assert back.parameters() == spec.parameters()


def test_the_spec_resolves_preset_calibration_overrides_poke_and_quantization(tmp_path):
    params = a_spec().parameters()
    short_ip01 = PlantParameters.preset(pendulum="short", cart="ip01")
    assert (params.Lp, params.M_cart) == (short_ip01.Lp, short_ip01.M_cart)
    assert (params.Beq, params.q_alpha, params.q_x) == (1.25, 2e-3, short_ip01.q_x)
    assert (params.poke_magnitude, params.poke_duration, params.poke_start) == (220.0, 0.005, 0.3)
    ideal = RunSpec(demo_controller(), quantization=Quantization(enabled=False)).parameters()
    assert ideal.q_alpha == 0.0 and ideal.q_x == 0.0
    calibration = tmp_path / "cal.json"
    calibration.write_text(json.dumps({"friction": {"F1": 1.0, "v1": 0.004, "F2": 2.5, "v2": 0.04, "B": 15.0}}))
    calibrated = RunSpec(demo_controller(), plant=Plant(calibration=str(calibration))).parameters()
    assert calibrated.friction == (1.0, 0.004, 2.5, 0.04, 15.0)


def test_a_spec_is_immutable_and_hashable():
    spec = a_spec()
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.timing = Timing()  # type: ignore[misc]
    with pytest.raises(TypeError):
        spec.plant.overrides["Beq"] = 2.0  # type: ignore[index]
    assert hash(spec) == hash(RunSpec.from_json(spec.to_json()))


def test_older_files_without_a_new_key_read_with_its_default():
    data = a_spec().to_dict()
    del data["timing"]["delay"], data["supervisor"]
    spec = RunSpec.from_dict(data)
    assert spec.timing.delay == 0 and spec.supervisor == Supervisor()


BAD = {
    "unknown section": ({"plants": {}}, "unknown section 'plants'"),
    "unknown key": ({"timing": {"stop": 1}}, "unknown key 'stop'"),
    "text for a number": ({"timing": {"stop_time": "5"}}, "timing.stop_time must be a number"),
    "fraction for a whole number": ({"timing": {"delay": 1.5}}, "timing.delay must be a whole number"),
    "not a table": ({"poke": [1, 2, 3]}, "poke must be a table"),
    "bad controller": ({"controller": {"transfer_function": {"kernel": {"zeros": [0], "poles": [-1], "gain": 1}}}}, "s/(s+62.8)"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_descriptions_name_what_is_wrong(case):
    data, words = BAD[case]
    with pytest.raises(UserError, match=None) as exc:
        RunSpec.from_dict(data, source="run.toml")
    assert words in str(exc.value) and "\n" not in str(exc.value)


RULES = {
    "stop time": (dict(timing=Timing(stop_time=-1.0)), "--stop-time -1.0 must be a positive number"),
    "step": (dict(timing=Timing(step=0.5)), "--step 0.5 must be within (0, 0.1] s"),
    "too many steps": (dict(timing=Timing(stop_time=1e9)), "a run has at most 2,000,000"),
    "delay": (dict(timing=Timing(delay=9)), "--delay 9 must be a whole number of control periods from 0 to"),
    "method": (dict(timing=Timing(method="euler")), "timing.method 'euler': choose tustin or zoh"),
    "poke duration": (dict(poke=Poke(50.0, -1.0, 0.5)), "--poke 50,-1,0.5: the magnitude must be finite"),
    "poke after the stop": (dict(poke=Poke(start=6.0)), "the poke starts at t=6 s, not before the stop time 5 s"),
    "alpha_max": (dict(supervisor=Supervisor(alpha_max=0.5)), "supervisor.alpha_max 0.5 rad must be 10 to 15 degrees"),
    "pendulum": (dict(plant=Plant(pendulum="medium")), "unknown pendulum 'medium'"),
    "override": (dict(plant=Plant(overrides={"Mq": 1.0})), "unknown plant parameter 'Mq'"),
    "calibration": (dict(plant=Plant(calibration="missing.json")), "calibration file missing.json does not exist"),
    "block": (dict(controller=ControllerSpec(fmu="missing.fmu")), "controller FMU missing.fmu does not exist"),
    "no controller": (dict(controller=ControllerSpec()), "a run needs one controller"),
}


@pytest.mark.parametrize("case", list(RULES))
def test_validate_holds_the_command_lines_rules(case):
    sections, words = RULES[case]
    sections = {"controller": demo_controller(), **sections}
    with pytest.raises(UserError) as exc:
        RunSpec(**sections).validate()
    assert words in str(exc.value)


def test_simulate_runs_the_spec_and_its_files_carry_it(tmp_path, loop_fmus):
    import pendulab

    spec = RunSpec(demo_controller("short"), plant=Plant(pendulum="short"), poke=Poke(220.0, 0.005, 0.2),
                   timing=Timing(stop_time=0.6, delay=1))
    result = pendulab.simulate(spec)
    assert result.spec is spec and len(result.columns["t"]) == 601
    # The same run described by its resolved parameters gives the same samples.
    old = pendulab.simulate(RunSpec.for_parameters(demo_controller("short"), spec.parameters(), timing=spec.timing))
    for name, column in old.columns.items():
        np.testing.assert_array_equal(result.columns[name], column, err_msg=name)
    assert old.metrics == result.metrics
    paths = result.write(tmp_path / "run")
    meta = scipy.io.loadmat(paths["mat"], squeeze_me=True)["meta"]
    assert str(meta["pendulum"]) == "short" and int(meta["delay"]) == 1
    # The run's meta is its serialization: the spec reads back from the file.
    assert RunSpec.from_json(str(meta["run"])) == spec
    assert json.loads(paths["metrics"].read_text())["stable"] == result.metrics["stable"]


def test_the_command_line_builds_the_spec_a_script_would(monkeypatch, tmp_path, loop_fmus):
    from pendulab.cli import simulate as cli_simulate
    from pendulab.cli.main import main

    seen = []
    real = cli_simulate.spec_from_args
    monkeypatch.setattr(cli_simulate, "spec_from_args", lambda args: seen.append(real(args)) or seen[-1])
    argv = ["simulate", "--pid", "600,200,5", "--pendulum", "short", "--poke", "220,0.005,0.2", "--stop-time", "0.4",
            "--delay", "2", "--method", "zoh", "--no-quantization", "--out", str(tmp_path / "cli")]
    assert main(argv) == 0
    assert seen == [RunSpec(Controller.pid(600, 200, 5), plant=Plant(pendulum="short"), poke=Poke(220.0, 0.005, 0.2),
                            timing=Timing(stop_time=0.4, method="zoh", delay=2), quantization=Quantization(enabled=False))]


def test_lab_compare_simulates_the_spec_at_the_rigs_delay(tmp_path, loop_fmus, capsys):
    """``pendulab lab --compare``: the session's spec (the rig's delay) simulated beside the rig's run."""
    from pendulab.analysis.compare import compare_with_simulation
    from pendulab.analysis.results import read_run
    from pendulab.simulation import simulate

    spec = RunSpec(demo_controller(), poke=Poke(220.0, 0.005, 0.5), timing=Timing(stop_time=2.0, delay=2))
    rig = tmp_path / "rig"
    simulate(spec.replace(timing=Timing(stop_time=2.0, delay=3))).write(rig)  # stands in for the rig's run
    text = compare_with_simulation(rig, spec, metrics={})
    _, meta = read_run(rig / "simulation")
    assert RunSpec.from_json(meta["run"]) == spec and int(meta["delay"]) == 2
    assert "natural frequency" in text and text in capsys.readouterr().out


def test_the_readmes_python_example_runs(tmp_path, monkeypatch, loop_fmus, capsys):
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    block = re.search(r"## In Python.*?```python\n(.*?)```", readme, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(block, "README.md", "exec"), {})
    assert (tmp_path / "runs" / "pid" / "run.mat").is_file() and capsys.readouterr().out.strip()
