"""The sweep spec: parsing, the grid, common random numbers, and one clear line for every bad spec."""

from __future__ import annotations

import numpy as np
import pytest

from pendulab.cli.main import main
from pendulab.sweep.spec import SpecError, parse_sweep_spec

ISSUE_SPEC = """
[run]
pendulum = "long"
stop_time = 5
poke = [220, 0.005, 1]

[controller.pid]
kp = [600, 750, 1200]
ki = [6, 20, 200]
kd = [5, 10, 20]

[uncertainty]
samples = 50
seed = 1
F1 = { uniform = [1.0, 2.0] }
Beq = { normal = [4.3, 0.4] }
delay = { choice = [1, 2, 3] }
"""


def test_the_issue_spec_is_a_27_point_grid_over_50_common_samples():
    spec = parse_sweep_spec(ISSUE_SPEC)
    assert (spec.n_points, spec.n_samples, spec.n_runs) == (27, 50, 1350)
    points = spec.points()
    assert points[0] == {"kp": 600.0, "ki": 6.0, "kd": 5.0} and points[-1] == {"kp": 1200.0, "ki": 200.0, "kd": 20.0}
    assert len({tuple(p.values()) for p in points}) == 27
    draws = spec.draws_table()
    # The draws follow their distributions (50 samples: loose bounds) and are reproducible.
    assert np.all((draws["F1"] >= 1.0) & (draws["F1"] <= 2.0))
    assert abs(np.mean(draws["Beq"]) - 4.3) < 0.2 and 0.25 < np.std(draws["Beq"]) < 0.55
    assert set(draws["delay"]) <= {1, 2, 3} and len(set(draws["delay"])) == 3
    again = parse_sweep_spec(ISSUE_SPEC).draws_table()
    assert all(np.array_equal(draws[k], again[k]) for k in draws)
    # Another seed draws other rigs; adding a parameter leaves the others' draws as they were.
    assert not np.array_equal(parse_sweep_spec(ISSUE_SPEC.replace("seed = 1", "seed = 2")).draws_table()["F1"], draws["F1"])
    more = parse_sweep_spec(ISSUE_SPEC + "M_cart = { uniform = [0.55, 0.6] }\n").draws_table()
    assert np.array_equal(more["F1"], draws["F1"]) and np.array_equal(more["delay"], draws["delay"])
    # Common random numbers: run (point g, sample s) gets sample s's rig whatever g is.
    from pendulab.sweep.spec import runs_of

    runs = list(runs_of(spec, [3, 50 + 3, 26 * 50 + 3]))
    assert [r[1:3] for r in runs] == [(0, 3), (1, 3), (26, 3)]
    assert len({(r[3]["F1"], r[3]["Beq"], r[3]["delay"]) for r in runs}) == 1
    run = spec.run_spec(runs[0][3]).validate()
    params = run.parameters()
    assert params.F1 == runs[0][3]["F1"] and params.Beq == runs[0][3]["Beq"] and params.poke_magnitude == 220
    assert run.timing.delay == runs[0][3]["delay"] and run.timing.stop_time == 5.0
    assert run.controller.transfer_function == spec.controller_at(spec.points()[0])


def test_a_grid_over_a_zero_of_the_controller_and_its_gain():
    spec = parse_sweep_spec('[controller]\ndemo = true\n[grid]\n"kernel.gain" = [30000, 40000]\n"compensators.0.zeros.0" = [-15, -17, -20]\n')
    assert spec.n_runs == 6
    c = spec.controller_at({"kernel.gain": 30000.0, "compensators.0.zeros.0": -15.0})
    assert c.kernel.gain == 30000 and c.compensators[0].zeros == (-15.0,) and c.kernel.poles == (7.0,)


def test_the_calibration_spread_draws_the_friction(tmp_path):
    import json

    cal = {"format": "pendulab-calibration", "version": 1, "friction": {"F1": 1.2, "v1": 0.004, "F2": 2.8, "v2": 0.05, "B": 18.0},
           "metadata": {"spread": {"F1": 0.1, "v1": 0.0, "F2": 0.3, "v2": 0.005, "B": 2.0, "Beq": 0.2}}}
    (tmp_path / "cal.json").write_text(json.dumps(cal))
    spec = parse_sweep_spec('[run]\ncalibration = "cal.json"\n[controller]\ndemo = true\n[uncertainty]\nsamples = 400\nspread = true\n',
                            base_dir=tmp_path)
    draws = spec.draws_table()
    assert set(draws) == {"F1", "F2", "v2", "B", "Beq"}  # v1's spread is 0: kept at its value
    assert abs(np.mean(draws["F1"]) - 1.2) < 0.03 and abs(np.std(draws["F1"]) - 0.1) < 0.02
    assert abs(np.mean(draws["Beq"]) - 4.3) < 0.06  # the preset's Beq, not fitted in this file
    assert parse_sweep_spec(spec.to_toml()).digest() == spec.digest()  # what sweep.toml records reads back


def test_a_spec_written_as_toml_reads_back_as_the_same_sweep():
    for text in (ISSUE_SPEC, '[controller]\ndemo = true\n[grid]\n"compensators.0.zeros.0" = [-15, -17]\n[sweep]\ntimeout = 5'):
        spec = parse_sweep_spec(text)
        again = parse_sweep_spec(spec.to_toml())
        assert again.digest() == spec.digest() and again.timeout == spec.timeout
        assert again.points() == spec.points() and again.draws() == spec.draws()


BAD = {
    "unknown parameter": ("[controller]\ndemo = true\n[uncertainty]\nsamples = 3\nFriction = { uniform = [1, 2] }\n", "uncertainty.Friction"),
    "low > high": ("[controller]\ndemo = true\n[uncertainty]\nsamples = 3\nF1 = { uniform = [2.0, 1.0] }\n", "uncertainty.F1.uniform"),
    "empty grid": ("[controller.pid]\nkp = []\nki = 6\nkd = 5\n", "controller.pid.kp"),
    "refused controller": ("[controller.pid]\nkp = [0, 600]\nki = 0\nkd = 0\n", "controller.pid"),
    "zero at s = 0": ('[controller]\ndemo = true\n[grid]\n"kernel.zeros.0" = [-5, 0]\n', "controller"),
    "unknown grid number": ('[controller]\ndemo = true\n[grid]\n"kernel.zeros.3" = [-5]\n', "grid.kernel.zeros.3"),
    "unknown run key": ("[run]\nstop = 3\n[controller]\ndemo = true\n", "run.stop"),
    "bad delay draw": ("[controller]\ndemo = true\n[uncertainty]\nsamples = 2\ndelay = { choice = [1, 1.5] }\n", "uncertainty.delay"),
    "negative sd": ("[controller]\ndemo = true\n[uncertainty]\nsamples = 2\nBeq = { normal = [4.3, -1] }\n", "uncertainty.Beq.normal"),
    "bad TOML": ("[controller\n", "not valid TOML"),
    "poke after the stop": ("[run]\nstop_time = 1\n[controller]\ndemo = true\n", "run: the poke starts at t=1 s"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_spec_is_one_line_naming_the_key_exit_2_and_no_folder(case, tmp_path, capsys):
    text, key = BAD[case]
    (tmp_path / "spec.toml").write_text(text)
    out = tmp_path / "out"
    assert main(["sweep", str(tmp_path / "spec.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("pendulab: error: ") and "Traceback" not in err
    assert key in err, err
    assert not out.exists()
    with pytest.raises(SpecError):
        parse_sweep_spec(text)


@pytest.mark.parametrize("options, key", [(["--workers", "0"], "--workers"), (["--scheduler", "bogus"], "--scheduler"),
                                          (["--scheduler", "local:x"], "local:N"), (["--resume"], "--resume")])
def test_bad_engine_options_are_one_line_before_anything_else(options, key, tmp_path, capsys):
    (tmp_path / "spec.toml").write_text("[run]\nstop_time = 2\n[controller.pid]\nkp = [600, 750]\nki = 6\nkd = 5\n")
    out = tmp_path / "out"
    assert main(["sweep", str(tmp_path / "spec.toml"), "--out", str(out), *options]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and key in err and not out.exists()
