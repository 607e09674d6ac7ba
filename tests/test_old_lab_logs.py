"""The old MATLAB lab's log folders: one .mat per signal, [t, value] at a variable time step, v5 or v7.3."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.io
from matfiles import save_mat73

from pendulab.calibration.logs import read_log, read_old_lab_folder
from pendulab.errors import UserError


def _variable_times(rng: np.random.Generator, duration: float) -> np.ndarray:
    steps = rng.uniform(0.5e-3, 1.5e-3, int(duration / 0.5e-3))
    t = np.concatenate(([0.0], np.cumsum(steps)))
    return t[t <= duration]


def alpha_true(t):
    return 0.05 * np.sin(7.0 * t)


def x_true(t):
    return 0.12 * np.sin(2.0 * t)


def v_true(t):
    return np.where(np.floor(t / 0.25) % 2 == 0, 2.0, -1.5)


def write_folder(folder, *, hanging=True, degrees=False, mm=False, v73=("position",), seed=0):
    rng = np.random.default_rng(seed)
    folder.mkdir()
    signals = {
        "angle": lambda t: (alpha_true(t) + (math.pi if hanging else 0.0)) * (180 / math.pi if degrees else 1.0),
        "position": lambda t: x_true(t) * (1e3 if mm else 1.0),
        "voltage": v_true,
    }
    for name, f in signals.items():
        t = _variable_times(rng, 2.0) + rng.uniform(0, 0.01)  # each signal starts a little differently
        data = np.column_stack([t, f(t)])
        if name in v73:
            save_mat73(folder / f"{name}.mat", {"data": data})
        else:
            scipy.io.savemat(folder / f"{name}.mat", {f"{name}Data": data})
    return folder


@pytest.mark.parametrize("options", [dict(), dict(hanging=False, v73=("angle", "voltage")), dict(degrees=True, mm=True)])
def test_folder_is_read_on_a_uniform_time_base_in_upright_radians_and_metres(tmp_path, options):
    columns = read_old_lab_folder(write_folder(tmp_path / "run", **options))
    t = columns["t"]
    assert set(columns) >= {"t", "alpha", "x", "voltage"}
    assert all(len(columns[k]) == len(t) for k in ("alpha", "x", "voltage"))
    steps = np.diff(t)
    assert np.ptp(steps) < 1e-9 and 0.4e-3 < steps[0] < 1.6e-3
    assert t[0] >= 0.0 and t[-1] <= 2.01
    # Interpolation of smooth signals sampled at ~1 ms: errors far below the signals' size.
    assert np.max(np.abs(columns["alpha"] - alpha_true(t))) < 2e-4
    assert np.max(np.abs(columns["x"] - x_true(t))) < 2e-4
    # The voltage is held: equal to the logged step signal except within one logged step of a switch.
    wrong = np.abs(columns["voltage"] - v_true(t)) > 1e-9
    assert wrong.mean() < 0.02


def test_read_log_accepts_an_old_lab_folder(tmp_path):
    folder = write_folder(tmp_path / "run")
    log = read_log(folder)
    assert log.alpha is not None and len(log) > 1000
    assert np.max(np.abs(log.x - x_true(log.t))) < 2e-4
    assert set(np.unique(log.V)) == {2.0, -1.5}


def _bad_folders(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    missing = write_folder(tmp_path / "missing")
    (missing / "voltage.mat").unlink()
    twice = write_folder(tmp_path / "twice")
    scipy.io.savemat(twice / "angle2.mat", {"a": np.ones((10, 2))})
    three = write_folder(tmp_path / "three")
    scipy.io.savemat(three / "position.mat", {"p": np.ones((10, 3))})
    apart = write_folder(tmp_path / "apart")
    scipy.io.savemat(apart / "voltage.mat", {"v": np.column_stack([np.linspace(10, 11, 50), np.ones(50)])})
    corrupt = write_folder(tmp_path / "corrupt")
    (corrupt / "angle.mat").write_bytes(b"not a mat file" * 20)
    return [
        (tmp_path / "nowhere", "does not exist"),
        (empty, "holds no .mat files"),
        (missing, "has no voltage file"),
        (twice, "two alpha files"),
        (three, "one two-column"),
        (apart, "do not overlap"),
        (corrupt, "not a readable MATLAB"),
    ]


def test_bad_folders_give_one_clear_line(tmp_path):
    for folder, words in _bad_folders(tmp_path):
        with pytest.raises(UserError, match=words) as info:
            read_old_lab_folder(folder)
        assert "\n" not in str(info.value), folder
