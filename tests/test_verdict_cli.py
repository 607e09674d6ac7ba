"""What a student reads is true (issue 24): one test per finding of the issue's second list.

The lead controller's first line and metrics.json; a poke that disturbs nothing; the track cut named in
the printed text, metrics.json, run.csv, run.mat and the plot; the cart speed change of the README's
kernel example; a reused --out; --pendulum none; tf --calibration. (Every README command's stated
outcome: tests/test_readme_commands.py; the GUI's placeholders, error words and reload:
tests/test_gui_browser.py.)
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.io

from pendulab.cli.main import main

LEAD = ["--zeros=-6,-12", "--poles=6.4,-90", "--gain", "40000"]
README_KERNEL = ["--zeros", "-6", "--poles", "6.4", "--gain", "45000", "--compensator", "-16;-80", "--compensator", ";-80"]


def simulate(capsys, *argv):
    status = main(["simulate", *argv])
    out, err = capsys.readouterr()
    return status, out, err


def test_lead_controller_first_line_and_metrics_name_saturation_chattering_drift(capsys, tmp_path, loop_fmus):
    status, out, err = simulate(capsys, *LEAD, "--out", str(tmp_path / "lead"))
    assert status == 0, err
    first = out.splitlines()[0]
    m = json.loads((tmp_path / "lead" / "metrics.json").read_text())
    v = m["verdict"]
    assert first == v["headline"]
    # The first line: balanced for 5 s, the chattering at +-10 V with its share at the limit, the drift with
    # the time to the track end.
    share = next(w for w in v["warnings"] if w["kind"] == "saturation")["value"]
    to_end = next(w for w in v["warnings"] if w["kind"] == "drift")["value"]
    assert first.startswith("BALANCED for 5 s, but the voltage chatters at ±10 V")
    assert f"(at the limit {100 * share:.0f} % of the time)" in first
    assert "the cart is drifting to the track end (about" in first and "after the run ends)" in first
    assert {w["kind"] for w in v["warnings"]} == {"saturation", "chattering", "drift", "small margin"}
    # Independent reading of run.csv: the share at +-10 V, the sign changes, the time to the track end.
    cols = np.genfromtxt(tmp_path / "lead" / "run.csv", delimiter=",", names=True)
    after = cols["t"] >= 1.0
    assert share == pytest.approx(np.mean(np.abs(cols["voltage"][after]) >= 10 - 1e-9), abs=2e-3) and share > 0.4
    big = cols["voltage"][after][np.abs(cols["voltage"][after]) > 2.5]
    assert np.count_nonzero(np.diff(np.sign(big))) / 4.0 > 50
    assert 0 <= to_end < 1.0 and abs(cols["x"][-1]) > 0.39
    # The metrics that would describe a second-order response are not reported, and say why.
    for key in ("natural_frequency_rad_s", "peak_time_s", "overshoot_percent", "settling_time_s"):
        assert m[key] is None and "chatters" in m["not_reported"][key]
    # The linear prediction beside it: the sampled loop is unstable (a limit cycle held by saturation).
    assert "linear model: UNSTABLE" in out and "DISAGREES with the simulation" in out


def test_lead_controller_is_cut_in_a_longer_run_as_its_drift_warning_said(capsys, tmp_path, loop_fmus):
    status, out, _ = simulate(capsys, *LEAD, "--stop-time", "10", "--out", str(tmp_path / "lead10"))
    assert status == 0
    m = json.loads((tmp_path / "lead10" / "metrics.json").read_text())
    assert out.startswith("CUT at t = 5.0") and m["safety_cut_reason"] == "track limit"
    assert 5.0 < m["safety_cut_time_s"] < 5.2


@pytest.mark.parametrize("poke, words", [("0,0.005,1", "--poke magnitude is 0"), ("50,0,1", "--poke duration is 0 s")])
def test_a_poke_that_disturbs_nothing_is_refused(capsys, tmp_path, poke, words):
    status, out, err = simulate(capsys, "--zeros=-1", "--poles=-5", "--gain", "-1000", "--poke", poke, "--out", str(tmp_path / "z"))
    assert status == 2 and out == "" and not (tmp_path / "z").exists()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"pendulab: error: {words}") and "disturbs nothing" in lines[0]


def test_the_python_api_calls_an_undisturbed_run_not_tested(loop_fmus):
    import pendulab
    from pendulab.control import parse_controller

    spec = pendulab.RunSpec(parse_controller("-1", "-5", "-1000"), poke=pendulab.Poke(0.0), timing=pendulab.Timing(stop_time=1.5))
    result = pendulab.simulate(spec)
    assert result.verdict.outcome == "not tested" and result.metrics["stable"] is False
    assert result.verdict.headline().startswith("NOT TESTED")


def test_the_track_cut_is_named_in_every_output(capsys, tmp_path, loop_fmus):
    out_dir = tmp_path / "pid"
    status, out, err = simulate(capsys, "--pid", "5000,0,500", "--out", str(out_dir))
    assert status == 0
    # Before simulating: why no PID alone can balance.
    assert "no gain can balance the pendulum with this controller" in err
    m = json.loads((out_dir / "metrics.json").read_text())
    cut = m["safety_cut_time_s"]
    assert out.startswith(f"CUT at t = {cut:.3f} s: the cart reached the track limit (0.40 m) with the pendulum still up")
    assert m["safety_cut_reason"] == "track limit" and m["verdict"]["cut_reason"] == "track limit"
    csv = np.genfromtxt(out_dir / "run.csv", delimiter=",", names=True)
    mat = scipy.io.loadmat(out_dir / "run.mat")
    for reasons, t in ((csv["trip_reason"], csv["t"]), (mat["trip_reason"].ravel(), mat["t"].ravel())):
        first = int(np.flatnonzero(reasons > 0)[0])
        assert reasons[first] == 2 and t[first] == pytest.approx(cut, abs=1.5e-3)  # 2: track limit
        assert abs(csv["x"][first]) >= 0.40 - 1e-3 and abs(csv["alpha"][first]) < math.radians(15)
    # The plot's cut line carries the reason; the saturated stretches are shaded.
    from pendulab.analysis.plots import run_figures

    columns = {name: csv[name] for name in csv.dtype.names}
    figures = dict(run_figures(columns, poke_start=1.0, safety_cut_time=cut))
    labels = [text.get_text() for text in figures["voltage.png"].axes[0].get_legend().get_texts()]
    assert "safety cut: track limit" in labels and "voltage at ±10 V" in labels


def test_the_cart_speed_change_of_the_readme_kernel_example(capsys, tmp_path, loop_fmus):
    """The issue: the last sample's speed said +0.0046 m/s; the cart's mean speed over the last second is negative."""
    status, out, _ = simulate(capsys, *README_KERNEL, "--out", str(tmp_path / "k"))
    assert status == 0 and out.startswith("BALANCED for 5 s with no warning")
    m = json.loads((tmp_path / "k" / "metrics.json").read_text())
    mat = scipy.io.loadmat(tmp_path / "k" / "run.mat")
    t, x = mat["t"].ravel(), mat["x"].ravel()
    net = (x[-1] - x[t >= t[-1] - 1.0][0]) / 1.0  # the net movement over the last second
    before = (x[t < 1.0][-1] - x[t >= 0.5][0]) / 0.5
    assert m["cart_speed_change_m_s"] == pytest.approx(net - before, abs=2e-4)
    assert m["cart_speed_change_m_s"] < -0.005  # moving left, as the cart does (-0.0087 m/s in the issue)


def test_a_reused_out_folder_never_keeps_another_runs_files(capsys, tmp_path, loop_fmus):
    out_dir = tmp_path / "run"
    assert simulate(capsys, "--demo", "--stop-time", "1.5", "--poke", "50,0.005,0.5", "--plot", "--ssp", "--out", str(out_dir))[0] == 0
    assert (out_dir / "run.png").is_file() and (out_dir / "loop.ssp").is_file()
    status, out, err = simulate(capsys, *README_KERNEL, "--stop-time", "1.5", "--poke", "50,0.005,0.5", "--out", str(out_dir))
    assert status == 2 and "holds an earlier run" in err and "--overwrite" in err
    status, out, err = simulate(capsys, *README_KERNEL, "--stop-time", "1.5", "--poke", "50,0.005,0.5", "--out", str(out_dir), "--overwrite")
    assert status == 0 and "removed the earlier run" in err and out.startswith("BALANCED")
    assert sorted(p.name for p in out_dir.iterdir()) == ["metrics.json", "run.csv", "run.mat"]


def test_pendulum_none_is_refused_with_the_reason(capsys, tmp_path):
    status, out, err = simulate(capsys, "--demo", "--pendulum", "none", "--out", str(tmp_path / "n"))
    assert status == 2 and out == ""
    assert err.strip() == ("pendulab: error: simulate needs a pendulum: --pendulum none is the cart alone, which has nothing to "
                           "balance (for the cart alone use 'pendulab calibrate --virtual'); choose --pendulum long or short")


def test_tf_calibration_says_what_the_linear_model_uses(capsys, tmp_path):
    from pendulab.calibration.files import Calibration, save_calibration

    friction_only = tmp_path / "friction.json"
    save_calibration(Calibration((2.0, 0.004, 3.5, 0.06, 25.0)), friction_only)
    assert main(["tf", "--calibration", str(friction_only)]) == 0
    first, note = capsys.readouterr().out.splitlines()[:2]
    assert first == "alpha/V = 5.247 s / ((s + 16.26)(s + 4.561)(s - 4.843))"  # friction does not change it
    assert "holds friction only" in note and "[2, 0.004, 3.5, 0.06, 25]" in note and "is not in it" in note
    fitted = tmp_path / "fitted.json"
    save_calibration(Calibration((2.0, 0.004, 3.5, 0.06, 25.0), Beq=5.0, force_gain=0.9), fitted)
    assert main(["tf", "--calibration", str(fitted)]) == 0
    first, note = capsys.readouterr().out.splitlines()[:2]
    assert first != "alpha/V = 5.247 s / ((s + 16.26)(s + 4.561)(s - 4.843))"
    assert "it uses Beq = 5, force_gain = 0.9" in note and "is not in it" in note


def test_the_readme_documents_the_supervisors_codes():
    """supervisor_state and trip_reason codes in the README are the Supervisor FMU's own."""
    import re
    from pathlib import Path

    from pendulab.fmu.models.supervisor.config import STATES, TRIP_REASONS

    readme = " ".join((Path(__file__).resolve().parents[1] / "README.md").read_text().split())
    states = readme.split("`supervisor_state` (the Supervisor FMU's `state`):", 1)[1].split("`trip_reason`:", 1)[0]
    reasons = readme.split("`trip_reason`:", 1)[1].split(". The verdict", 1)[0]
    for table, text in ((STATES, states), (TRIP_REASONS, reasons)):
        found = {int(code): name for code, name in re.findall(r"(\d) ([a-z][a-z -]*?)(?= \(|,|\.|$)", text)}
        assert found == table, (found, table)
