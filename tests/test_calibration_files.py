"""Calibration files: JSON and the old lab's .mat, validation, atomic writing, applying to parameters."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from pendulab.calibration.files import (
    DEFAULT_CALIBRATION_PATH,
    Calibration,
    default_calibration,
    load_calibration,
    save_calibration,
)
from pendulab.errors import CalibrationError, UserError
from pendulab.model.parameters import PlantParameters

REPO = Path(__file__).resolve().parents[1]
GOOD = {"friction": {"F1": 2.0, "v1": 0.004, "F2": 3.5, "v2": 0.06, "B": 25.0}, "Beq": 5.0, "force_gain": 0.9}


def write(tmp_path: Path, data, name: str = "cal.json") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def test_default_file_is_the_lab_table_and_the_packaged_copy_matches_the_repository():
    assert default_calibration().friction == (1.5, 0.005, 3.0, 0.05, 20.0)
    assert DEFAULT_CALIBRATION_PATH.read_text() == (REPO / "calibration" / "default.json").read_text()


def test_round_trip_and_apply(tmp_path):
    cal = load_calibration(write(tmp_path, GOOD))
    assert cal.friction == (2.0, 0.004, 3.5, 0.06, 25.0)
    params = cal.apply(PlantParameters.preset("long"))
    assert (params.F1, params.B, params.Beq, params.force_gain) == (2.0, 25.0, 5.0, 0.9)
    assert params.M_cart == PlantParameters.preset("long").M_cart  # not in the file: unchanged
    again = load_calibration(save_calibration(cal, tmp_path / "copy.json"))
    assert again == cal


@pytest.mark.parametrize(
    "data, words",
    [
        ("{not json", "not valid JSON"),
        ({"Beq": 4.0}, "missing 'friction'"),
        ({"friction": {"F1": 1.5, "v1": 0.005}}, "missing F2, v2, B"),
        ({"friction": {**GOOD["friction"], "F1": "strong"}}, "F1='strong' is not a number"),
        ({"friction": {**GOOD["friction"], "B": -1.0}}, "B=-1 is negative"),
        ({"friction": {**GOOD["friction"], "v1": 0.1}}, "v1=0.1 m/s is above v2"),
        ({"friction": {**GOOD["friction"], "F1": 5.0}}, "F1=5 N is above F2"),
        ({**GOOD, "force_gain": 0}, "force_gain must be > 0"),
        ({**GOOD, "Beq": 1e9}, "Beq=1000000000.0 is outside its range 0 to 10000"),  # the plant's (and the FMU's) range
        ({**GOOD, "beq": 4.0}, "unknown entry 'beq'"),
        ({"friction": [1, 2, 3]}, "needs 5 numbers"),
        ([1, 2], "expected a JSON object"),
    ],
)
def test_malformed_files_give_one_clear_line(tmp_path, data, words):
    path = write(tmp_path, data)
    with pytest.raises(CalibrationError) as info:
        load_calibration(path)
    message = str(info.value)
    assert words in message and "\n" not in message and str(path) in message
    assert isinstance(info.value, UserError)


def test_a_byte_order_mark_is_read(tmp_path):
    """Windows Notepad's "UTF-8" starts a file with a byte-order mark: the calibration is read as without it."""
    path = tmp_path / "notepad.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(GOOD).encode())
    assert load_calibration(path) == load_calibration(write(tmp_path, GOOD))


def test_missing_and_unreadable_files(tmp_path):
    with pytest.raises(CalibrationError, match="does not exist"):
        load_calibration(tmp_path / "nope.json")
    binary = tmp_path / "binary.json"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(CalibrationError, match="cannot be read|not valid JSON"):
        load_calibration(binary)


def test_old_lab_mat_file_with_five_numbers(tmp_path):
    path = tmp_path / "fric.mat"
    scipy.io.savemat(path, {"friction": np.array([[2.0, 0.004, 3.5, 0.06, 25.0]]), "other": np.arange(12.0)})
    assert load_calibration(path).friction == (2.0, 0.004, 3.5, 0.06, 25.0)


@pytest.mark.parametrize("name", ["defaultData", "measuredData", "fv"])
def test_old_lab_mat_file_with_four_numbers_reads_as_the_old_lab_did(tmp_path, name):
    # The old lab's real file: [F1 v1 B unused]; its static-friction function fixed F2 = 4 F1, v2 = 0.1 m/s.
    path = tmp_path / "old.mat"
    scipy.io.savemat(path, {name: np.array([[1.2, 0.01, 0.0, 0.0]])})
    cal = load_calibration(path)
    assert cal.friction == pytest.approx((1.2, 0.01, 4.8, 0.1, 0.0))
    assert cal.metadata["mat_variable"] == name
    assert "[F1, v1, B, unused]" in cal.metadata["note"]
    scipy.io.savemat(path, {name: np.array([2.0, 0.004, 25.0, 7.0])})
    assert load_calibration(path).friction == pytest.approx((2.0, 0.004, 8.0, 0.1, 25.0))


def test_old_lab_mat_file_v73_hdf5(tmp_path):
    from matfiles import save_mat73

    path = save_mat73(tmp_path / "measured.mat", {"measuredData": np.array([[1.5, 0.005, 20.0, 0.0]])})
    assert load_calibration(path).friction == pytest.approx((1.5, 0.005, 6.0, 0.1, 20.0))


def test_empty_old_lab_mat_file_is_one_clear_error(tmp_path):
    path = tmp_path / "empty.mat"
    scipy.io.savemat(path, {"defaultData": np.zeros((0, 0))})
    with pytest.raises(CalibrationError, match="is empty") as info:
        load_calibration(path)
    assert "\n" not in str(info.value)
    scipy.io.savemat(path, {})
    with pytest.raises(CalibrationError, match="holds no friction vector"):
        load_calibration(path)


@pytest.mark.parametrize(
    "contents, words",
    [
        ({"x": np.arange(10.0)}, "holds no friction vector"),
        ({"a": np.ones(5), "b": np.ones(4)}, "several 4/5-number vectors"),
        ({"defaultData": np.array([0.5, 0.2, 3.0, 0.0])}, "v1=0.2 m/s is above v2=0.1"),
        ({"friction": np.array([1.0, 0.1, 2.0, 0.05, 3.0])}, "v1=0.1 m/s is above v2"),
    ],
)
def test_bad_mat_files(tmp_path, contents, words):
    path = tmp_path / "bad.mat"
    scipy.io.savemat(path, contents)
    with pytest.raises(CalibrationError, match=words):
        load_calibration(path)


def test_corrupt_mat_file(tmp_path):
    path = tmp_path / "corrupt.mat"
    path.write_bytes(b"MATLAB 5.0 MAT-file, but then nothing sensible" + bytes(200))
    with pytest.raises(CalibrationError, match="not a readable MATLAB"):
        load_calibration(path)


def test_save_is_atomic_and_leaves_nothing_half_written(tmp_path, monkeypatch):
    target = tmp_path / "cal.json"
    save_calibration(Calibration((1.0, 0.001, 2.0, 0.01, 5.0)), target)
    before = target.read_text()

    # A failure while writing keeps the old file and leaves no temporary file behind.
    import pendulab.calibration.files as files

    real_fdopen = files.os.fdopen

    class Exploding:
        def __init__(self, fd, *a, **k):
            self.handle = real_fdopen(fd, *a, **k)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.handle.close()

        def write(self, text):
            self.handle.write(text[: len(text) // 2])
            raise OSError("disk full")

    monkeypatch.setattr(files.os, "fdopen", Exploding)
    from pendulab.errors import CalibrationError

    with pytest.raises(CalibrationError, match="disk full"):  # one line for the user, not a traceback
        save_calibration(Calibration((2.0, 0.004, 3.5, 0.06, 25.0)), target)
    assert target.read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cal.json"]


def test_save_to_a_directory_is_a_user_error(tmp_path):
    with pytest.raises(CalibrationError, match="is a directory"):
        save_calibration(Calibration((1.0, 0.001, 2.0, 0.01, 5.0)), tmp_path)
