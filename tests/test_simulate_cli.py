"""``pendulab simulate`` (SPEC §7, §10): flags, controller files, outputs; every bad input is one
stderr line with exit status 2, no traceback, and nothing already in the output folder is lost.

Most cases run in-process through :func:`pendulab.cli.main.main` (fast); a few run the real commands
(``/work/venv/bin/pendulab`` or ``python -m pendulab``) as subprocesses.
"""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from pendulab.analysis.results import read_run
from pendulab.cli.main import main
from pendulab.control.controller import Controller, demo_controller

#: A short run with an early poke (seconds of simulated time cost little; the defaults are 5 s, poke at 1 s).
SHORT = ["--stop-time", "1.5", "--poke", "220,0.005,0.3"]
#: The demo controller written out factor by factor, for the flags and file forms.
DEMO_FLAGS = ["--zeros=-5", "--poles=7", "--gain", "40000", "--compensator=-17;-80", "--compensator=none;-80"]
DEMO_TOML = """\
[kernel]
zeros = [-5]
poles = [7]
gain = 40000

[[compensators]]
zeros = [-17]
poles = [-80]

[[compensators]]
poles = [-80]
"""
DEMO_JSON = {"kernel": {"zeros": [-5], "poles": [7], "gain": 40000}, "compensators": [{"zeros": [-17], "poles": [-80]}, {"poles": [-80]}]}


def pendulab_command() -> list[str]:
    """The installed console script next to this interpreter (the venv's ``bin/pendulab``)."""
    script = Path(sys.executable).with_name("pendulab")
    return [str(script)] if script.exists() else [shutil.which("pendulab") or "pendulab"]


def simulate(capsys, *args: str) -> tuple[int, str, str]:
    """``pendulab simulate ARGS`` in-process: (exit status, stdout, stderr)."""
    status = main(["simulate", *args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


@pytest.fixture(autouse=True)
def not_a_terminal(monkeypatch):
    """stdin is not a terminal (no interactive prompt), as in a script or CI."""
    monkeypatch.setattr(sys, "stdin", io.StringIO(""))


def test_the_demo_controller_in_its_written_forms():
    for ours, demo in zip(Controller.from_dict(DEMO_JSON).zpk(), demo_controller().zpk()):
        np.testing.assert_array_equal(np.sort_complex(np.atleast_1d(ours)), np.sort_complex(np.atleast_1d(demo)))


# ---------------------------------------------------------------- flags and files that work
def test_flags_toml_and_json_give_the_same_run(capsys, tmp_path, loop_fmus):
    (tmp_path / "c.toml").write_text(DEMO_TOML)
    (tmp_path / "c.json").write_text(json.dumps(DEMO_JSON))
    runs = {}
    for form, args in {
        "flags": DEMO_FLAGS,
        "toml": ["--controller", str(tmp_path / "c.toml")],
        "json": ["--controller", str(tmp_path / "c.json")],
        "demo": ["--demo"],
    }.items():
        out = tmp_path / form
        status, stdout, stderr = simulate(capsys, *args, *SHORT, "--out", str(out))
        assert status == 0, stderr
        assert stdout.startswith("BALANCED for 1.5 s") and str(out) in stdout
        assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "run.csv", "run.mat"]
        runs[form] = read_run(out / "run.mat")[0]
    for form in ("toml", "json", "demo"):
        for name, column in runs["flags"].items():
            np.testing.assert_array_equal(runs[form][name], column, err_msg=f"{form}: {name}")


def test_pid_short_pendulum_zoh_and_ideal_encoders(capsys, tmp_path, loop_fmus):
    out = tmp_path / "pid"
    status, stdout, stderr = simulate(
        capsys, "--pid", "-40,-5,-4", "--pendulum", "short", "--method", "zoh", "--no-quantization", *SHORT, "--out", str(out)
    )
    assert status == 0, stderr
    columns, meta = read_run(out / "run.mat")
    assert meta["pendulum"] == "short" and meta["discretization"] == "zoh"
    assert meta["parameters"]["Lp"] == pytest.approx(0.3365)
    assert "62.8" in meta["controller"]  # the PID's derivative filter pole
    np.testing.assert_array_equal(columns["alpha_measured"], columns["alpha"])  # no quantization
    assert set(json.loads((out / "metrics.json").read_text())) >= {"stable", "safety_cut_time_s"}


def test_poke_and_stop_time_reach_the_simulation(capsys, tmp_path, loop_fmus):
    out = tmp_path / "poke"
    status, _, stderr = simulate(capsys, "--demo", "--poke", "-100,0.01,0.25", "--stop-time", "0.8", "--out", str(out))
    assert status == 0, stderr
    columns, meta = read_run(out / "run.mat")
    assert columns["t"][-1] == pytest.approx(0.8) and len(columns["t"]) == 801
    p = meta["parameters"]
    assert (p["poke_magnitude"], p["poke_duration"], p["poke_start"]) == (-100.0, 0.01, 0.25)
    t, alpha = columns["t"], columns["alpha"]
    assert np.all(alpha[t < 0.25] == 0) and alpha[np.searchsorted(t, 0.26)] < 0  # a negative poke swings to -alpha


def test_a_new_run_folder_under_runs_by_default(capsys, tmp_path, monkeypatch, loop_fmus):
    monkeypatch.chdir(tmp_path)
    for _ in range(2):
        status, _, stderr = simulate(capsys, "--demo", "--stop-time", "0.5", "--poke", "50,0.005,0.1")
        assert status == 0, stderr
    folders = sorted((tmp_path / "runs").iterdir())
    assert len(folders) == 2 and all(f.name.endswith("long") or f.name.endswith("long-2") for f in folders)
    assert all((f / "run.mat").is_file() for f in folders)


# ---------------------------------------------------------------- bad input
BAD_INPUTS = {
    "gain not a number": ["--zeros=-5", "--poles=7", "--gain", "abc"],
    "zero not a number": ["--zeros=abc", "--poles=7", "--gain", "1"],
    "gain zero": ["--poles=-1", "--gain", "0"],
    "gain not finite": ["--poles=-1", "--gain", "nan"],
    "pole at zero": ["--poles=0", "--gain", "1"],
    "zero at zero": ["--zeros=0", "--poles=-1", "--gain", "1"],
    "improper controller": ["--zeros=-1,-2", "--poles=-1", "--gain", "1"],
    "complex pole without conjugate": ["--poles=-1+2j", "--gain", "1"],
    "seven factors": ["--poles=-1", "--gain", "1", *["--compensator=-1;-2"] * 6],
    "order 17": ["--poles=" + ",".join(str(-k) for k in range(1, 18)), "--gain", "1"],
    "pole at 2/h for tustin": ["--poles=2000", "--gain", "1"],
    "kernel without gain": ["--zeros=-1", "--poles=-2"],
    "compensator without kernel": ["--compensator=-1;-2"],
    "malformed compensator": ["--demo", "--compensator=abc"],
    "two controllers": ["--demo", "--pid", "1,2,3"],
    "no controller": [],
    "bad pid": ["--pid", "1,2"],
    "pid all zero": ["--pid", "0,0,0"],
    "unknown pendulum": ["--poles=-1", "--gain", "1", "--pendulum", "medium"],
    "unknown pendulum for the demo": ["--demo", "--pendulum", "medium"],
    "unknown cart": ["--demo", "--cart", "foo"],
    "poke with two numbers": ["--demo", "--poke", "50,0.005"],
    "poke not numbers": ["--demo", "--poke", "a,b,c"],
    "poke negative duration": ["--demo", "--poke", "50,-1,0.5"],
    "poke not finite": ["--demo", "--poke", "inf,0.005,0.5"],
    "poke after stop time": ["--demo", "--poke", "50,0.005,6", "--stop-time", "5"],
    "poke at stop time": ["--demo", "--poke", "50,0.005,2", "--stop-time", "2"],
    "poke that blows up the plant": ["--demo", "--poke", "1e300,1,0.2", "--stop-time", "0.5"],
    "negative stop time": ["--demo", "--stop-time", "-1"],
    "zero stop time": ["--demo", "--stop-time", "0"],
    "stop time not a number": ["--demo", "--stop-time", "abc"],
    "stop time not finite": ["--demo", "--stop-time", "inf"],
    "too many steps": ["--demo", "--stop-time", "1e9"],
    "step too small": ["--demo", "--step", "1e-9"],
    "step too large": ["--demo", "--step", "0.5"],
    "unknown method": ["--demo", "--method", "euler"],
    "unknown flag": ["--demo", "--frobnicate"],
    "missing controller file": ["--controller", "{tmp}/missing.toml"],
    "controller file of unknown type": ["--controller", "{tmp}/controller.txt"],
    "malformed TOML": ["--controller", "{tmp}/bad.toml"],
    "JSON with an unknown key": ["--controller", "{tmp}/extra.json"],
    "improper controller file": ["--controller", "{tmp}/improper.json"],
    "controller file is a folder": ["--controller", "{tmp}/folder.toml"],
    "missing calibration file": ["--demo", "--calibration", "{tmp}/missing.json"],
    "malformed calibration file": ["--demo", "--calibration", "{tmp}/bad.json"],
}


@pytest.fixture(scope="module")
def bad_files(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("bad")
    (tmp / "controller.txt").write_text(DEMO_TOML)
    (tmp / "bad.toml").write_text("[kernel]\nzeros = [-5\npoles = [7]\n")
    (tmp / "extra.json").write_text(json.dumps({**DEMO_JSON, "extra": 1}))
    (tmp / "improper.json").write_text(json.dumps({"kernel": {"zeros": [-1, -2], "poles": [-3], "gain": 1}}))
    (tmp / "folder.toml").mkdir()
    (tmp / "bad.json").write_text("{not json")
    return tmp


@pytest.fixture(scope="module")
def previous_run(tmp_path_factory) -> tuple[Path, dict[str, bytes]]:
    """An output folder holding the files of an earlier run (and a note of the student's)."""
    out = tmp_path_factory.mktemp("previous") / "run"
    out.mkdir()
    for name in ("run.mat", "run.csv", "metrics.json", "angle.png", "notes.txt"):
        (out / name).write_bytes(f"earlier {name}".encode())
    return out, {p.name: p.read_bytes() for p in out.iterdir()}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_is_one_line_and_exit_2(capsys, case, bad_files, previous_run, loop_fmus):
    out, files = previous_run
    args = [a.replace("{tmp}", str(bad_files)) for a in BAD_INPUTS[case]]
    status, stdout, stderr = simulate(capsys, *args, "--plot", "--out", str(out))
    assert status == 2
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("pendulab: error: "), stderr
    assert "Traceback" not in stderr + stdout and len(lines[0]) < 400
    # The earlier run's files are untouched and nothing was added.
    assert {p.name: p.read_bytes() for p in out.iterdir()} == files


@pytest.mark.parametrize(
    "case, words",
    [
        ("zero at zero", "s/(s+62.8)"),
        ("pole at zero", "1/(s+0.1)"),
        ("improper controller", "improper"),
        ("poke after stop time", "--stop-time"),
        ("order 17", "16"),
        ("missing controller file", "missing.toml"),
    ],
)
def test_errors_name_the_value_and_the_fix(capsys, case, words, bad_files, tmp_path):
    args = [a.replace("{tmp}", str(bad_files)) for a in BAD_INPUTS[case]]
    status, _, stderr = simulate(capsys, *args, "--out", str(tmp_path / "out"))
    assert status == 2 and words in stderr
    assert not (tmp_path / "out").exists()


def test_out_is_an_existing_file(capsys, tmp_path):
    target = tmp_path / "taken"
    target.write_text("keep me")
    status, _, stderr = simulate(capsys, "--demo", "--out", str(target))
    assert status == 2 and "is a file" in stderr and target.read_text() == "keep me"


# ---------------------------------------------------------------- the real commands
def test_console_script_writes_plots_animation_and_ssp(tmp_path, loop_fmus):
    from fmpy.ssp.ssd import read_ssd

    (tmp_path / "c.toml").write_text(DEMO_TOML)
    out = tmp_path / "out"
    result = subprocess.run(
        [*pendulab_command(), "simulate", "--controller", str(tmp_path / "c.toml"), "--pendulum", "short",
         *SHORT, "--plot", "--animate", "--ssp", "--out", str(out)],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL,
    )
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    names = {p.name for p in out.iterdir()}
    assert {"run.mat", "run.csv", "metrics.json", "rig.gif", "loop.ssp"} <= names
    assert len([n for n in names if n.endswith(".png")]) >= 4  # angle, tip, cart position, voltage
    assert (out / "rig.gif").read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    for png in out.glob("*.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    ssd = read_ssd(str(out / "loop.ssp"), validate=True)
    assert [e.name for e in ssd.system.elements] == ["plant", "controller", "supervisor"]
    mat = scipy.io.loadmat(out / "run.mat", squeeze_me=True, struct_as_record=False)
    assert mat["meta"].pendulum == "short"
    assert not [p for p in out.iterdir() if p.name.startswith(".")], "no temporary files left"


@pytest.mark.parametrize("how", ["console script", "python -m"])
def test_real_commands_report_a_bad_input_in_one_line(tmp_path, how):
    command = pendulab_command() if how == "console script" else [sys.executable, "-m", "pendulab"]
    args = ["--zeros=0", "--poles=-1", "--gain", "1"] if how == "python -m" else ["--demo", "--poke", "50,0.005,9"]
    result = subprocess.run(
        [*command, "simulate", *args, "--out", str(tmp_path / "out")],
        capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
    )
    assert result.returncode == 2
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("pendulab: error: ") and "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()
