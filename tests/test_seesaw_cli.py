"""``pendulab tf --plant seesaw`` and ``pendulab lqr`` (issue 20, build 2 and 3; must-show 5)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pendulab.cli.main import main
from pendulab.control.state_feedback import load_state_feedback_file
from pendulab.model.seesaw import linearize_seesaw


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_tf_of_the_seesaw_prints_theta_x_and_the_poles_and_json_agrees_with_the_model(capsys) -> None:
    status, out, _ = run(capsys, "tf", "--plant", "seesaw")
    assert status == 0
    lines = out.splitlines()
    assert lines[0].startswith("theta/V = ") and lines[1].startswith("x/V = ") and lines[2].startswith("open-loop poles: ")
    assert "(s - 2.892)" in lines[0]  # the seesaw alone falls: one pole in the right half-plane
    status, out, _ = run(capsys, "tf", "--plant", "seesaw", "--json")
    data = json.loads(out)
    poles = np.array([complex(re, im) for re, im in data["poles"]])
    np.testing.assert_allclose(np.sort_complex(poles), np.sort_complex(np.linalg.eigvals(linearize_seesaw().ss.A)), rtol=1e-9)
    for output in ("theta", "x"):
        num, den = data[output]["num"], data[output]["den"]
        # The transfer function at s = 1j equals C (sI - A)^-1 B of the state-space model.
        ss = linearize_seesaw().ss
        row = ("theta", "x").index(output)
        expected = (ss.C[row] @ np.linalg.solve(1j * np.eye(4) - ss.A, ss.B))[0]
        assert np.polyval(num, 1j) / np.polyval(den, 1j) == pytest.approx(expected, rel=1e-9)
        assert num[1] == 0.0  # an even numerator: zeros mirrored about the imaginary axis


def test_tf_of_the_pendulum_is_unchanged_by_the_plant_option(capsys) -> None:
    _, default, _ = run(capsys, "tf")
    _, explicit, _ = run(capsys, "tf", "--plant", "pendulum")
    assert default == explicit == "alpha/V = 5.247 s / ((s + 16.26)(s + 4.561)(s - 4.843))\n"


def test_lqr_for_the_seesaw_reproduces_quanser_and_writes_a_controller_file(capsys, tmp_path: Path) -> None:
    out_file = tmp_path / "ssw.toml"
    status, out, _ = run(capsys, "lqr", "--plant", "seesaw", "--json", "--out", str(out_file))
    assert status == 0
    data = json.loads(out)
    assert data["states"] == ["x", "theta", "xdot", "thetadot", "theta_integral"]
    np.testing.assert_allclose(data["K"], [180.797, -224.3485, 16.6684, -66.9969, -63.2456], rtol=2e-5)
    assert all(re < 0 for re, _ in data["closed_loop_poles"])
    design = load_state_feedback_file(str(out_file))
    np.testing.assert_array_equal(design.K, data["K"])
    assert design.integral_limit == pytest.approx(np.radians(10))


def test_lqr_for_the_pendulum_stabilizes_its_linear_model(capsys) -> None:
    status, out, _ = run(capsys, "lqr", "--plant", "pendulum", "--q", "100,1000,0,0", "--r", "0.5", "--json")
    data = json.loads(out)
    assert status == 0 and data["states"] == ["x", "alpha", "xdot", "alphadot"]
    assert max(re for re, _ in data["closed_loop_poles"]) < 0


@pytest.mark.parametrize(
    "argv, words",
    [
        (["lqr", "--plant", "seesaw", "--q", "1,2,3"], "--q has 3 weights"),
        (["lqr", "--plant", "seesaw", "--q", "1,2,x,4"], "--q '1,2,x,4' must be numbers"),
        (["lqr", "--r", "-0.5"], "--r must be a finite number > 0"),
        (["lqr", "--r", "nan"], "--r must be a finite number > 0"),
        (["lqr", "--q", "1,-2,0,0"], "must be finite and >= 0"),
        (["lqr", "--plant", "cart"], "invalid choice"),
        (["lqr", "--out", "k.json"], "must be a .toml"),
        (["tf", "--plant", "seesaw", "--demo"], "takes no controller"),
    ],
)
def test_bad_lqr_and_tf_input_is_one_line_and_exit_2(capsys, argv: list[str], words: str) -> None:
    status, out, err = run(capsys, *argv)
    assert status == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and words in err


def test_a_pendulum_controller_file_is_not_a_state_feedback_file(tmp_path: Path) -> None:
    from pendulab.errors import UserError

    path = tmp_path / "pendulum.toml"
    path.write_text("[kernel]\nzeros = [-6]\npoles = [6.4]\ngain = 45000\n")
    with pytest.raises(UserError, match="no \\[state_feedback\\] table"):
        load_state_feedback_file(str(path))
