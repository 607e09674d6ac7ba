"""'pendulab calibrate', 'pendulab fit' and 'pendulab tf --calibration' from the command line."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pendulab.calibration.files import load_calibration
from pendulab.calibration.synthetic import TEST_RIG
from pendulab.cli.main import main
from pendulab.model.linear import linearize
from pendulab.model.parameters import PlantParameters

TRUE = TEST_RIG.friction


def run(capsys, *argv: str) -> tuple[int, str, str]:
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def only_file(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("calibrate")
    out, log = folder / "cal.json", folder / "ramp.csv"
    status = main(["calibrate", "--virtual", "--iterations", "1", "--friction", ",".join(map(str, TRUE)), "--out", str(out), "--log", str(log)])
    assert status == 0
    return out, log


def test_calibrate_virtual_writes_the_scaled_vector(calibrated):
    out, _ = calibrated
    cal = load_calibration(out)
    ratio = cal.metadata["mass_ratio"]
    assert ratio == pytest.approx((0.57 + 0.230) / 0.57)  # long pendulum by default
    measured = cal.metadata["measured_friction"]
    for name, true in zip(("F1", "v1", "F2", "v2", "B"), TRUE):
        assert abs(measured[name] / true - 1) < 0.10, name
    assert cal.friction[0] == pytest.approx(ratio * measured["F1"]) and cal.friction[4] == measured["B"]
    assert cal.metadata["iterations"] == 1 and "spread" in cal.metadata and "date" in cal.metadata


def test_calibrate_prints_progress_per_iteration(capsys, tmp_path):
    status, out, _ = run(capsys, "calibrate", "--virtual", "--iterations", "2", "--out", str(tmp_path / "c.json"), "--backend", "casadi")
    assert status == 0
    assert "iteration 1/2" in out and "iteration 2/2" in out
    assert "F1 = " in out and "±" in out and "calibration written to" in out


@pytest.mark.parametrize(
    "argv, words",
    [
        (["calibrate"], "--port PORT for the real rig"),
        (["calibrate", "--virtual", "--friction", "1,2,3"], "needs 5 numbers"),
        (["calibrate", "--virtual", "--friction", "3,0.005,1,0.05,20"], "F1=3 N is above F2"),
        (["calibrate", "--virtual", "--iterations", "0"], "must be at least 1"),
    ],
)
def test_calibrate_user_errors(capsys, tmp_path, argv, words):
    status, _, err = run(capsys, *argv, "--out", str(tmp_path / "cal.json"))
    assert status == 2 and words in err and err.count("\n") == 1
    assert only_file(tmp_path) == []


def test_calibrate_out_is_a_directory_or_empty(capsys, tmp_path):
    status, _, err = run(capsys, "calibrate", "--virtual", "--out", str(tmp_path))
    assert status == 2 and "is a directory" in err
    status, _, err = run(capsys, "calibrate", "--virtual", "--out", "")
    assert status == 2 and "--out is empty" in err


def test_without_virtual_through_the_console_script(tmp_path):
    result = subprocess.run([sys.executable, "-m", "pendulab", "calibrate"], capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.startswith("pendulab: error:") and result.stderr.count("\n") == 1 and "Traceback" not in result.stderr


def swing(x_unit: float, V_unit: float, x_offset: float = 0.0) -> str:
    """A cart swung by a sine of 2 V (1 kHz, 0.6 s), its x and V in other units (or signs), x from another zero."""
    return "t,V,x\n" + "".join(f"{k * 1e-3:.3f},{V_unit * 2 * math.sin(k / 100):.6g},{x_offset + x_unit * 0.02 * (1 - math.cos(k / 100)):.6g}\n"
                                for k in range(600))


def bad_logs(folder: Path) -> dict[str, tuple[Path, str]]:
    t = np.arange(0, 2.0, 1e-3)
    cases = {
        "missing column": ("t,V\n0,0\n0.001,1\n", "no column x (found: t, V); a log needs columns t, V, x (s, V, m), each a vector: rename the column in the header (x is read from x or x_measured)"),
        "time backwards": ("t,V,x\n0,0,0\n0.002,0.1,0\n0.001,0.2,0\n", "time is not increasing"),
        "NaN": ("t,V,x\n0,0,0\n0.001,0.1,nan\n0.002,0.2,0\n", "x is not finite"),
        "too short": ("t,V,x\n" + "".join(f"{k * 1e-3},{k * 0.01},{k * 1e-6}\n" for k in range(12)), "too short"),
        "never moves": ("t,V,x\n" + "".join(f"{tt:.3f},{min(tt, 0.5):.4f},0.001\n" for tt in t), "never moves"),
        # Units and signs a log made elsewhere gets wrong: each named before any work.
        "t in ms": ("t,V,x\n" + "".join(f"{k},{2 * math.sin(k / 100):.4f},{0.02 * (1 - math.cos(k / 100)):.6f}\n" for k in range(600)),
                    "if t is in milliseconds, give it in seconds"),
        "x in mm": (swing(1e3, 1.0), "give x in metres"),
        "V in mV": (swing(1.0, 1e3), "give V in volts"),
        "against V": (swing(-1.0, 1.0), "V or x has the wrong sign"),
        "x from the track's end": (swing(1.0, 1.0, x_offset=0.5), "give x from the track's centre"),
        "x just past the end": (swing(1.0, 1.0, x_offset=0.376), "x reaches 0.416 m, beyond the track's ends"),  # 9 mm past it
        "first step": ("t,V,x\n-0.0004,0,0\n" + swing(1.0, 1.0).split("\n", 2)[2], "the sample period varies from 1 to 1.4 ms"),
        # What a rig's log may carry: missing samples, a lost encoder count, the pendulum left on (helper's audit).
        "samples missing": ("".join(line + "\n" for k, line in enumerate(swing(1.0, 1.0).splitlines()) if not 301 <= k <= 310),
                            "(the most off, 11 ms, after t = 0.299 s); split the log where samples are missing"),
        "x jumps": ("t,V,x\n" + "".join(f"{t_},{V_},{float(x_) + (0.02 if k >= 300 else 0.0):.6g}\n"
                                       for k, (t_, V_, x_) in enumerate(line.split(",") for line in swing(1.0, 1.0).splitlines()[1:])),
                    "x jumps by 20 mm after t = 0.299 s"),
        "pendulum on": ("t,V,x,alpha\n" + "".join(f"{line},{0.1 * math.sin(k / 50):.4f}\n" for k, line in enumerate(swing(1.0, 1.0).splitlines()[1:])),
                        "alpha swings over 0.2 rad: the pendulum is on the cart; fit with its model (--pendulum long or short)"),
    }
    paths = {}
    for i, (name, (text, words)) in enumerate(cases.items()):
        path = folder / f"log{i}.csv"
        path.write_text(text)
        paths[name] = (path, words)
    return paths


def test_fit_malformed_logs_one_line_exit_2_nothing_written(capsys, tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    for name, (path, words) in bad_logs(logs).items():
        status, _, err = run(capsys, "fit", str(path), "--out", str(out_dir / "fit.json"), "--plot", str(out_dir / "fit.png"))
        # A cart that never moves is a log that determines nothing: exit 3, saying what to record instead.
        assert status == (3 if name == "never moves" else 2), name
        assert words in err and err.count("\n") == 1 and err.startswith("pendulab: error:"), (name, err)
        assert only_file(out_dir) == [], name
    # One dead log among several: leave it out.
    good = logs / "good.csv"
    good.write_text(swing(1.0, 1.0))
    status, _, err = run(capsys, "fit", str(good), str(bad_logs(logs)["never moves"][0]), "--out", str(out_dir / "fit.json"))
    assert status == 3 and "never moves" in err and "leave it out, or record" in err and only_file(out_dir) == [], err


def test_fit_bad_options(capsys, calibrated, tmp_path):
    _, log = calibrated
    for argv, words in [
        (["--fit", "F1,Mp"], "cannot fit 'Mp'"),
        (["--fit", ""], "--fit: no parameter named"),
        (["--out", ""], "--out is empty"),  # an unset "$OUT" in a script: refused, not a fit that writes nothing
        (["--plot", ""], "--plot is empty"),
        (["--plot", str(tmp_path / "fit.jpg")], "must be a .png file"),
        (["--out", str(tmp_path)], "is a directory"),
        (["--calibration", str(tmp_path / "missing.json")], "does not exist"),
    ]:
        status, _, err = run(capsys, "fit", str(log), *argv)
        assert status == 2 and words in err and err.count("\n") == 1, argv


def test_fit_end_to_end_on_the_calibrate_log(capsys, calibrated, tmp_path):
    _, log = calibrated
    out, plot = tmp_path / "fit.json", tmp_path / "fit.png"
    status, text, _ = run(capsys, "fit", str(log), "--out", str(out), "--plot", str(plot), "--scale-for", "long")
    assert status == 0 and "one-sample prediction RMS" in text and "forward simulation" in text
    cal = load_calibration(out)
    assert abs(cal.Beq / 4.3 - 1) < 0.05 and abs(cal.force_gain - 1) < 0.05
    assert abs(cal.friction[0] / (TRUE[0] * cal.metadata["mass_ratio"]) - 1) < 0.10
    assert plot.read_bytes()[:4] == b"\x89PNG"
    assert only_file(tmp_path) == ["fit.json", "fit.png"]


def tf_json(capsys, *argv: str) -> dict:
    status, out, err = run(capsys, "tf", "--json", *argv)
    assert status == 0, err
    return json.loads(out)


def test_tf_follows_the_fitted_Beq_and_force_gain(capsys, tmp_path):
    path = tmp_path / "fitted.json"
    path.write_text(json.dumps({"friction": dict(zip(("F1", "v1", "F2", "v2", "B"), TRUE)), "Beq": 6.5, "force_gain": 0.8}))
    plain = tf_json(capsys)
    calibrated = tf_json(capsys, "--calibration", str(path))
    expected = linearize(PlantParameters.preset("long", Beq=6.5, force_gain=0.8)).zpk("alpha")
    assert calibrated["gain"] == pytest.approx(expected[2], rel=1e-9)
    assert calibrated["gain"] == pytest.approx(0.8 * plain["gain"], rel=1e-9)  # gain scales with the force gain
    assert sorted(calibrated["poles"]) == pytest.approx(sorted(np.real(expected[1])), rel=1e-9)
    assert sorted(calibrated["poles"]) != pytest.approx(sorted(plain["poles"]), rel=1e-3)  # Beq moves the poles
    # The friction vector alone leaves the linear model unchanged.
    friction_only = tmp_path / "friction.json"
    friction_only.write_text(json.dumps({"friction": dict(zip(("F1", "v1", "F2", "v2", "B"), TRUE))}))
    assert tf_json(capsys, "--calibration", str(friction_only)) == plain


@pytest.mark.parametrize(
    "text, words",
    [("{", "not valid JSON"), ('{"friction": {"F1": 1}}', "missing v1, F2, v2, B"), ('{"friction": [1, 0.1, 2, 0.01, 3]}', "v1=0.1 m/s is above v2")],
)
def test_tf_with_a_malformed_calibration_file(capsys, tmp_path, text, words):
    path = tmp_path / "bad.json"
    path.write_text(text)
    status, out, err = run(capsys, "tf", "--calibration", str(path))
    assert status == 2 and words in err and err.count("\n") == 1 and out == ""
