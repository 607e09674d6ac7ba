"""The one output rule (:mod:`pendulab.outputs`): checked before any work, never overwriting an earlier run
without ``--overwrite``, atomic files with the user's umask; and every command that writes follows it."""

from __future__ import annotations

import os
import stat
import sys
import time

import pytest

from pendulab.cli.main import main
from pendulab.errors import UserError
from pendulab.outputs import atomic_write, check_output_file, check_run_folder, earlier_run_files

#: A place even root cannot write (sysfs refuses new files); Linux only.
READONLY = "/sys/pendulab-test"
needs_sysfs = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="sysfs is Linux")


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    return err[0]


def _earlier_run(folder):
    folder.mkdir()
    for name in ("rig_log.csv", "run.mat", "run.csv", "metrics.json", "timing.json"):
        (folder / name).write_text(f"earlier {name}")
    (folder / "notes.txt").write_text("the TA's notes")
    return {p.name: p.read_text() for p in folder.iterdir()}


def test_a_folder_with_an_earlier_run_is_refused_and_kept(tmp_path):
    before = _earlier_run(tmp_path / "run")
    with pytest.raises(UserError, match=r"holds an earlier run .*--overwrite"):
        check_run_folder(tmp_path / "run")
    assert {p.name: p.read_text() for p in (tmp_path / "run").iterdir()} == before


def test_overwrite_removes_only_the_earlier_run_and_says_so(tmp_path):
    _earlier_run(tmp_path / "run")
    (tmp_path / "run" / "simulation").mkdir()
    (tmp_path / "run" / "simulation" / "run.mat").write_text("x")
    folder = check_run_folder(tmp_path / "run", overwrite=True)
    assert (tmp_path / "run" / "run.mat").exists()  # nothing removed by the check itself
    said: list[str] = []
    folder.prepare(announce=said.append)
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["notes.txt"]
    assert len(said) == 1 and "removed the earlier run" in said[0] and "run.mat" in said[0]


def test_a_folder_with_only_other_files_is_accepted(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "notes.txt").write_text("mine")
    assert check_run_folder(tmp_path / "run").earlier == []
    assert earlier_run_files(tmp_path / "run") == []


@pytest.mark.parametrize("make, message", [
    (lambda p: p.mkdir(), "is a directory"),
    (lambda p: p.write_text("{}"), "exists"),
])
def test_output_file_refusals(tmp_path, make, message):
    target = tmp_path / "c.json"
    make(target)
    with pytest.raises(UserError, match=message):
        check_output_file(target, "--out")


def test_output_file_under_a_file_and_wrong_suffix(tmp_path):
    (tmp_path / "f").write_text("")
    with pytest.raises(UserError, match="is a file, not a folder"):
        check_output_file(tmp_path / "f" / "sub" / "c.json")
    with pytest.raises(UserError, match=r"must be a \.png file"):
        check_output_file(tmp_path / "plot.jpg", "--plot", suffixes=(".png",))
    assert not (tmp_path / "f.json").exists()


@needs_sysfs
def test_an_unwritable_place_is_found_by_trying_even_as_root(tmp_path):
    with pytest.raises(UserError, match="cannot write in /sys"):
        check_output_file(READONLY + "/c.json")
    with pytest.raises(UserError, match="cannot write in /sys"):
        check_run_folder(READONLY + "/run")


def test_files_get_the_users_umask_calibrations_included(tmp_path):
    """Calibration files were 0600 (mkstemp); now 0666 less the umask, like a run folder's files."""
    from pendulab.calibration.files import Calibration, save_calibration

    old = os.umask(0o022)
    try:
        cal = save_calibration(Calibration((1.0, 0.001, 2.0, 0.01, 5.0)), tmp_path / "c.json")
        other = atomic_write(tmp_path / "a.txt", lambda f: f.write(b"x"))
        os.umask(0o002)
        group = atomic_write(tmp_path / "g.txt", lambda f: f.write(b"x"))
    finally:
        os.umask(old)
    assert stat.S_IMODE(cal.stat().st_mode) == 0o644
    assert stat.S_IMODE(other.stat().st_mode) == 0o644
    assert stat.S_IMODE(group.stat().st_mode) == 0o664
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "c.json", "g.txt"]  # no temporaries left


# ------------------------------------------------------------------ the commands, in process
def test_lab_into_an_earlier_session_is_refused_before_connecting(tmp_path, capsys):
    before = _earlier_run(tmp_path / "session")
    # The port does not exist: had the folder not been checked first, the error would be about the port.
    assert main(["lab", "--port", str(tmp_path / "ttyNONE"), "--demo", "--out", str(tmp_path / "session")]) == 2
    line = _one_line(capsys)
    assert "holds an earlier run" in line and "--overwrite" in line
    assert {p.name: p.read_text() for p in (tmp_path / "session").iterdir()} == before


def test_simulate_into_an_earlier_run(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", "--demo", "--stop-time", "1.5", "--out", str(out)]) == 0
    first = (out / "run.csv").read_bytes()
    capsys.readouterr()
    assert main(["simulate", "--pid", "40,5,4", "--stop-time", "1.5", "--out", str(out)]) == 2
    assert "holds an earlier run" in _one_line(capsys)
    assert (out / "run.csv").read_bytes() == first
    assert main(["simulate", "--pid", "40,5,4", "--stop-time", "1.5", "--out", str(out), "--overwrite"]) == 0
    assert "removed the earlier run" in capsys.readouterr().err  # stderr: simulate's stdout starts with the verdict
    assert (out / "run.csv").read_bytes() != first


@needs_sysfs
@pytest.mark.parametrize("argv", [
    ["calibrate", "--virtual", "--log", READONLY + "/log.csv", "--out", "{tmp}/c.json"],
    ["calibrate", "--virtual", "--out", READONLY + "/c.json"],
    ["lab", "--port", "loop://", "--demo", "--out", READONLY + "/lab"],
    ["fit", "{tmp}/missing.csv", "--plot", READONLY + "/f.png"],
    ["fit", "{tmp}/missing.csv", "--out", READONLY + "/f.json"],
    ["compare", "{tmp}/missing", "--out", READONLY],
    ["simulate", "--demo", "--out", READONLY + "/sim"],
])
def test_every_command_checks_its_outputs_before_any_work(tmp_path, capsys, argv):
    started = time.process_time()
    assert main([a.replace("{tmp}", str(tmp_path)) for a in argv]) == 2
    assert "cannot write in /sys" in _one_line(capsys)
    assert time.process_time() - started < 2.0  # no ramp test, no connection, no fit ran first
    assert list(tmp_path.iterdir()) == []
