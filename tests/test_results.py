"""run.mat / run.csv / metrics.json writing and reading, and the streamed RunLog."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import scipy.io

from pendulab.analysis.results import COLUMNS, RunLog, atomic_write, read_run, write_results
from pendulab.errors import UserError
from pendulab.model.parameters import PlantParameters


def make_columns(n: int = 200) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(1)
    t = np.arange(n) * 1e-3
    cols = {name: rng.normal(size=n) for name in COLUMNS}
    cols["t"] = t
    cols["alpha"] = 0.1 * np.sin(7.0 * t) / 3.0  # values that have no short decimal form
    cols["supervisor_state"] = np.where(t < 0.1, 1.0, 2.0)
    return cols


META = {
    "controller": {"kernel": {"zeros": [-1.0, -3.0], "poles": [-20.0, -30.0, -40.0], "gain": 12.5}, "text": "12.5 (s+1)(s+3)/..."},
    "parameters": PlantParameters.preset(pendulum="short"),
    "calibration": {"friction": [1.5, 0.005, 3.0, 0.05, 20.0], "file": "calibration/default.json"},
    "pendulum": "short",
}
METRICS = {"natural_frequency_rad_s": 4.2, "peak_time_s": None, "stable": True}


@pytest.fixture
def written(tmp_path):
    cols = make_columns()
    paths = write_results(tmp_path / "run1", cols, META, METRICS)
    return cols, paths


def test_write_results_writes_three_files_and_no_leftovers(written):
    _, paths = written
    assert set(paths) == {"mat", "csv", "metrics"}
    folder = paths["mat"].parent
    assert sorted(p.name for p in folder.iterdir()) == ["metrics.json", "run.csv", "run.mat"]
    assert json.loads(paths["metrics"].read_text()) == METRICS
    assert paths["metrics"].read_text().startswith('{\n  "')  # indent 2


def test_run_mat_is_matlab5_with_column_vectors_of_doubles(written):
    cols, paths = written
    assert paths["mat"].read_bytes()[:19] == b"MATLAB 5.0 MAT-file"
    content = scipy.io.loadmat(paths["mat"])
    for name in COLUMNS:
        assert content[name].shape == (len(cols["t"]), 1), name
        assert content[name].dtype == np.float64, name
        np.testing.assert_array_equal(content[name][:, 0], cols[name])


def test_meta_struct_fields_are_readable_from_matlab_style_load(written):
    _, paths = written
    meta = scipy.io.loadmat(paths["mat"], squeeze_me=True, struct_as_record=False)["meta"]
    assert set(meta._fieldnames) >= {"controller", "parameters", "calibration", "pendulum", "version"}
    assert meta.pendulum == "short"
    assert isinstance(meta.version, str) and meta.version
    assert meta.parameters.Lp == pytest.approx(0.3365)
    assert meta.parameters.q_alpha == pytest.approx(0.001)
    np.testing.assert_allclose(meta.controller.kernel.poles, [-20.0, -30.0, -40.0])
    assert meta.controller.kernel.gain == 12.5
    np.testing.assert_allclose(meta.calibration.friction, [1.5, 0.005, 3.0, 0.05, 20.0])


def test_meta_defaults_and_none_become_empty(tmp_path):
    paths = write_results(tmp_path, make_columns(5), {"controller": "5/(s+1)", "calibration": None}, {})
    meta = scipy.io.loadmat(paths["mat"], squeeze_me=True, struct_as_record=False)["meta"]
    assert meta.controller == "5/(s+1)"
    assert np.size(meta.calibration) == 0 and np.size(meta.parameters) == 0
    _, read_meta = read_run(paths["mat"])
    assert read_meta["calibration"] is None and read_meta["controller"] == "5/(s+1)"


@pytest.mark.parametrize("which", ["mat", "csv"])
def test_round_trip_through_read_run_is_exact(written, which):
    cols, paths = written
    columns, meta = read_run(paths[which])
    for name in COLUMNS:
        if which == "mat" or name == "supervisor_state":  # short decimals read back exactly from the CSV too
            np.testing.assert_array_equal(columns[name], cols[name])
        else:  # the CSV keeps 15 significant digits
            np.testing.assert_allclose(columns[name], cols[name], rtol=1e-14, atol=0)
    if which == "mat":
        assert meta["pendulum"] == "short"
        assert meta["parameters"]["Mp"] == pytest.approx(0.127)
        assert meta["controller"]["kernel"]["poles"] == [-20.0, -30.0, -40.0]
    else:
        assert meta == {}


def test_read_run_on_a_folder_prefers_the_mat_file(written):
    _, paths = written
    _, meta = read_run(paths["mat"].parent)
    assert meta["pendulum"] == "short"
    paths["mat"].unlink()
    columns, meta = read_run(paths["mat"].parent)
    assert meta == {} and set(COLUMNS) <= set(columns)


def test_extra_columns_are_kept(tmp_path):
    cols = make_columns(10) | {"trip_reason": np.arange(10.0)}
    paths = write_results(tmp_path, cols, {}, {})
    for which in ("mat", "csv"):
        np.testing.assert_array_equal(read_run(paths[which])[0]["trip_reason"], np.arange(10.0))


def test_rewriting_replaces_the_previous_run(written):
    _, paths = written
    cols = make_columns(7)
    write_results(paths["mat"].parent, cols, META, {"stable": False})
    assert read_run(paths["csv"])[0]["t"].size == 7
    assert json.loads(paths["metrics"].read_text()) == {"stable": False}


def test_metrics_json_never_holds_nan(tmp_path):
    paths = write_results(tmp_path, make_columns(5), {}, {"x": float("nan"), "y": np.float64(2.5), "ok": np.bool_(True)})
    assert json.loads(paths["metrics"].read_text()) == {"x": None, "y": 2.5, "ok": True}


def test_failed_write_leaves_no_partial_file(tmp_path, monkeypatch):
    out = tmp_path / "out"

    def broken_savemat(f, *args, **kwargs):
        f.write(b"MATLAB 5.0 half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(scipy.io, "savemat", broken_savemat)
    with pytest.raises(UserError, match="No space left"):
        write_results(out, make_columns(5), {}, {})
    assert list(out.iterdir()) == []


def test_failed_csv_write_in_its_thread_leaves_no_partial_file(tmp_path, monkeypatch):
    # run.csv is written by a thread beside run.mat and metrics.json: its failure is reported the same
    # way, and the files already written by the other thread are removed too.
    import pendulab.analysis.results as results

    out = tmp_path / "out"

    def broken_blocks(names, data):
        yield b"t,x\n"
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(results, "_csv_blocks", broken_blocks)
    with pytest.raises(UserError, match="No space left"):
        write_results(out, make_columns(5), {}, {})
    assert list(out.iterdir()) == []


def test_atomic_write_keeps_the_old_file_when_the_writer_fails(tmp_path):
    target = tmp_path / "plot.png"
    target.write_bytes(b"old")

    def fail(f):
        f.write(b"new but broken")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        atomic_write(target, fail)
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["plot.png"]


def test_write_results_rejects_bad_columns(tmp_path):
    cols = make_columns(5)
    with pytest.raises(ValueError, match="lack tip"):
        write_results(tmp_path, {k: v for k, v in cols.items() if k != "tip"}, {}, {})
    with pytest.raises(ValueError, match="differ in length"):
        write_results(tmp_path, cols | {"x": np.zeros(4)}, {}, {})
    assert list(tmp_path.iterdir()) == []


def test_output_folder_that_is_a_file_is_a_user_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(UserError, match="is a file"):
        write_results(blocker, make_columns(3), {}, {})


@pytest.mark.parametrize(
    "setup, match",
    [
        (lambda d: d / "missing.mat", "does not exist"),
        (lambda d: d, "no run.mat or run.csv"),
        (lambda d: _write(d / "run.txt", "t\n1\n"), "neither a .mat nor a .csv"),
        (lambda d: _write(d / "run.mat", "not a mat file at all"), "cannot read"),
        (lambda d: _write(d / "run.csv", "t,x\n0.0,1.0\n"), "lacks column"),
        (lambda d: _write(d / "run.csv", ",".join(COLUMNS) + "\n1,2,three\n"), "malformed"),
        (lambda d: _write(d / "run.csv", ""), "empty"),
    ],
)
def test_read_run_errors_are_one_line_user_errors(tmp_path, setup, match):
    with pytest.raises(UserError, match=match) as info:
        read_run(setup(tmp_path))
    assert "\n" not in str(info.value)


def _write(path, text):
    path.write_text(text)
    return path


def test_mat_missing_columns_is_a_user_error(tmp_path):
    path = tmp_path / "other.mat"
    scipy.io.savemat(path, {"t": np.zeros((3, 1)), "alpha": np.zeros((3, 1))})
    with pytest.raises(UserError, match="lacks column.*x, xdot"):
        read_run(path)


# ---------------------------------------------------------------------------------------- RunLog
def test_runlog_flushes_every_n_rows_and_reads_back(tmp_path):
    path = tmp_path / "log" / "run.csv"
    log = RunLog(path, flush_every=3)
    rows = [[k * 1e-3] + [k + 0.1 * i for i in range(len(COLUMNS) - 1)] for k in range(7)]
    for row in rows[:2]:
        log.append(row)
    assert path.read_text().count("\n") == 1  # header only: nothing flushed yet
    log.append(rows[2])
    assert path.read_text().count("\n") == 4  # header + 3 rows
    for row in rows[3:]:
        log.append(dict(zip(COLUMNS, row)))
    assert log.rows == 7
    assert log.close() == path and log.closed
    log.close()  # idempotent
    columns, _ = read_run(path)
    np.testing.assert_array_equal(np.column_stack([columns[c] for c in COLUMNS]), np.array(rows))
    with pytest.raises(ValueError, match="closed"):
        log.append(rows[0])


def test_runlog_validates_rows_and_columns(tmp_path):
    with RunLog(tmp_path / "a.csv", ("t", "V")) as log:
        with pytest.raises(ValueError, match="2 columns"):
            log.append([1.0])
        with pytest.raises(ValueError, match="lacks column 'V'"):
            log.append({"t": 1.0})
    with pytest.raises(ValueError, match="MATLAB-style"):
        RunLog(tmp_path / "b.csv", ("t", "bad name"))


def test_runlog_open_failure_is_a_user_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(UserError, match="cannot open log file"):
        RunLog(blocker / "run.csv")


def test_read_run_drops_the_partial_last_row_of_a_crashed_log(tmp_path):
    path = tmp_path / "run.csv"
    with RunLog(path, flush_every=1) as log:
        for k in range(4):
            log.append([k] * len(COLUMNS))
    with open(path, "a") as f:
        f.write("4.0,4.0,4.")  # the crash happened in the middle of a write
    columns, _ = read_run(path)
    np.testing.assert_array_equal(columns["t"], [0.0, 1.0, 2.0, 3.0])


def test_runlog_rows_survive_a_process_that_never_closes(tmp_path):
    path = tmp_path / "run.csv"
    code = (
        "import os\n"
        "from pendulab.analysis.results import RunLog\n"
        f"log = RunLog({str(path)!r}, ('t', 'V'), flush_every=2)\n"
        "for k in range(5): log.append((k, -k))\n"
        "os._exit(1)\n"  # dies without closing: only whole flushed rows remain
    )
    subprocess.run([sys.executable, "-c", code], check=False)
    assert path.read_text() == "t,V\n0.0,0.0\n1.0,-1.0\n2.0,-2.0\n3.0,-3.0\n"
    assert os.path.getsize(path) > 0


def test_csv_numbers_match_python_formatting_to_15_digits():
    # An independent reference: Python's own '%.15g' (correctly rounded) for every kind of number the
    # writer handles; the vectorized rounding may differ from it by one unit in the 15th digit on a tie.
    from pendulab.analysis.results import csv_bytes

    rng = np.random.default_rng(3)
    values = np.concatenate([
        rng.normal(size=3000) * 10.0 ** rng.integers(-30, 30, size=3000),
        [0.0, -0.0, 1.0, -1.0, 10.0, 0.1, 1e-3, 1e-4, 1e-5, 1e14, 1e15, 1e16, 2.0, -2.5, 1234.5, 120.0,
         9.999999999999999, 99999999999999.9, 0.30000000000000004, 1e-300, -1e300, 5e-324,
         np.nan, np.inf, -np.inf, 123456789012345678.0,
         -1.2345678901234567e-290],  # beyond the table's exponents, and its repr is 24 characters long
    ])
    text = csv_bytes(["v"], values[:, None]).decode()
    lines = text.split("\n")
    assert lines[0] == "v" and lines[-1] == "" and len(lines) == values.size + 2
    for value, line in zip(values, lines[1:-1]):
        if np.isfinite(value):
            unit = 10.0 ** (np.floor(np.log10(abs(value))) - 14) if value else 0.0
            assert abs(float(line) - float("%.15g" % value)) <= 1.5 * unit, (value, line)
            assert len(line.lstrip("-").replace(".", "").split("e")[0]) <= 15
        else:
            assert line == repr(float(value))
    assert lines[1 + 3000 : 1 + 3016] == ["0", "0", "1", "-1", "10", "1e-1", "1e-3", "1e-4", "1e-5",
                                          "100000000000000", "1e15", "1e16", "2", "-2.5", "1.2345e3", "120"]
    assert csv_bytes(["a", "b"], np.zeros((0, 2))) == b"a,b\n"
