"""Calibration logs: CSV and run.mat/run.csv of 'pendulab simulate', and every way a log can be broken."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from pendulab.calibration.logs import RampLog, read_log, write_log
from pendulab.errors import CalibrationError


def csv_file(tmp_path: Path, text: str, name: str = "log.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_plain_csv_with_comments_and_extra_columns(tmp_path):
    path = csv_file(tmp_path, "# ramp test\nt,V,x,note\n0,0,0.001,a\n0.001,0.5,0.001,b\n0.002,1.0,0.0011,c\n")
    log = read_log(path)
    assert np.allclose(log.t, [0, 0.001, 0.002]) and np.allclose(log.V, [0, 0.5, 1.0]) and log.alpha is None
    assert log.source == str(path)


def test_simulate_run_csv_uses_voltage_and_the_measured_angle(tmp_path):
    header = "t,x,xdot,alpha,alpha_measured,tip,voltage_command,voltage,supervisor_state"
    rows = [f"{k * 1e-3},{k * 1e-4},0.1,{k * 1e-3},{k * 1e-3 + 0.5},0,{9.0},{k * 0.1},running" for k in range(5)]
    log = read_log(csv_file(tmp_path, header + "\n" + "\n".join(rows) + "\n", "run.csv"))
    assert np.allclose(log.V, [0.0, 0.1, 0.2, 0.3, 0.4])  # 'voltage' (applied), not the command
    assert np.allclose(log.alpha, np.arange(5) * 1e-3 + 0.5)  # alpha_measured preferred


def test_a_mat_log_without_the_vectors_says_to_name_the_variables(tmp_path):
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, {"data": np.zeros((20, 3))})  # one n x 3 matrix: no vector named t, V or x
    with pytest.raises(CalibrationError, match=r"\(found: none\); a log needs columns t, V, x \(s, V, m\), each a vector: name the variable"):
        read_log(path)


def test_simulate_run_mat(tmp_path):
    n = 20
    t = np.arange(n) * 1e-3
    path = tmp_path / "run.mat"
    scipy.io.savemat(
        path,
        {"t": t[:, None], "x": (t * 0.1)[:, None], "voltage": np.ones((n, 1)), "alpha": np.zeros((n, 1)),
         "alpha_measured": np.zeros((n, 1)), "meta": {"pendulum": "long"}},
    )
    log = read_log(path)
    assert len(log) == n and np.allclose(log.x, t * 0.1) and np.allclose(log.V, 1.0)


def test_write_and_read_back(tmp_path):
    log = RampLog(np.arange(4) * 1e-3, np.array([0, 0.1, 0.2, 0.3]), np.array([0, 0, 1e-5, 3e-5]), events=((0.0, "start"),))
    again = read_log(write_log(log, tmp_path / "out.csv"))
    assert np.allclose(again.x, log.x) and np.allclose(again.V, log.V)


@pytest.mark.parametrize(
    "text, words",
    [
        ("t,V\n0,0\n0.001,1\n", "no column x"),
        ("time,x\n0,0\n0.001,1\n", "no column V"),
        ("t,V,x\n0,0,0\n0.002,0,0\n0.001,0,0\n", "time is not increasing at sample 3"),
        ("t,V,x\n0,0,0\n0.001,nan,0\n", "V is not finite"),
        ("t,V,x\n0,0,0\n0.001,zero,0\n", "V='zero' is not a number"),
        ("t,V,x\n0,0,0\n0.001,,0\n", "V='' is not a number; fill the cell or remove the row"),
        ("t;V;x\n0;0;0\n0,001;1,5;0\n", "is not a number; write numbers with a decimal point, not a comma"),
        ("t,V,x,V\n0,0,0,0\n0.001,1,0,1\n", "column V appears twice in the header"),
        ("t,V,x\n1000,0,0\n1000,0,0\n", "a repeated time stamp: write t with more digits"),
        ("t,V,x\n0,0,0\n0.001,0\n", "2 fields but the header (line 1: 't,V,x') has 3"),
        ("LabVIEW measurement\nrig 3\nt,V,x\n0,0,0\n", "line 3: 1 fields but the header (line 1: 'LabVIEW measurement') has 2; remove any lines above the header"),
        ("0,0,0\n0.001,0,0\n", "no header line"),
        ("t,V,x\n0,0,0\n", "1 sample(s)"),
        ("", "is empty"),
    ],
)
def test_malformed_logs_give_one_clear_line(tmp_path, text, words):
    path = csv_file(tmp_path, text)
    with pytest.raises(CalibrationError) as info:
        read_log(path)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_a_byte_order_mark_is_read_and_other_encodings_are_named(tmp_path):
    """Excel's "CSV UTF-8" starts with a byte-order mark: the columns are found; a Latin-1 file gets one line saying
    what to save it as."""
    log = read_log(csv_file(tmp_path, "\ufefft,V,x\n0,0,0\n0.001,1,0\n0.002,1,0.001\n"))
    assert np.array_equal(log.x, [0, 0, 0.001])
    excel = read_log(csv_file(tmp_path, "sep=;\r\nt;V;x\r\n0;0;0\r\n0.001;1;0\r\n", "excel.csv"))  # its separator line
    assert np.array_equal(excel.V, [0, 1])
    latin = tmp_path / "latin.csv"
    latin.write_bytes("# rig 3, 20 \u00b0C\nt,V,x\n0,0,0\n0.001,1,0\n".encode("latin-1"))
    with pytest.raises(CalibrationError) as info:
        read_log(latin)
    assert "is not UTF-8 text" in str(info.value) and "save it as UTF-8" in str(info.value) and "\n" not in str(info.value)


def test_missing_log_and_non_mat_file(tmp_path):
    with pytest.raises(CalibrationError, match="does not exist"):
        read_log(tmp_path / "missing.csv")
    bad = tmp_path / "bad.mat"
    bad.write_text("not a mat file")
    with pytest.raises(CalibrationError, match="not a readable MATLAB"):
        read_log(bad)


@pytest.mark.parametrize("first, second", [("14:03:07.125", "14:03:07.126"), ("2026-11-28 23:59:59.999", "2026-11-29 00:00:00.000"),
                                           ("2026-11-28T14:03:07.125+01:00", "2026-11-28T14:03:07.126+01:00")])
def test_a_time_column_of_clock_times_is_read_as_seconds_from_its_first(tmp_path, first, second):
    """A logger or a spreadsheet writes the time of day (with or without its date): the log starts at t = 0."""
    log = read_log(csv_file(tmp_path, f"time,V,x\n{first},0,0\n{second},0.5,0\n"))
    assert log.t.tolist() == [0.0, 0.001]
    with pytest.raises(CalibrationError, match=r"time='14:03:61' is not a number"):  # not a clock time either
        read_log(csv_file(tmp_path, "time,V,x\n14:03:07,0,0\n14:03:61,0.5,0\n"))
    with pytest.raises(CalibrationError, match=r"line 3: .* has no time zone and the first row's time has the other"):  # was a TypeError
        read_log(csv_file(tmp_path, "time,V,x\n2026-11-28T14:03:07+01:00,0,0\n2026-11-28T14:03:08,0.5,0\n"))
