"""PNG plots, root locus, the rig animation, and the students' example script."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import control
import matplotlib.image
import numpy as np
import pytest
from PIL import Image

from pendulab.analysis.animation import animate_run
from pendulab.analysis.plots import plot_root_locus, plot_run, root_locus_branches
from pendulab.analysis.results import write_results
from pendulab.errors import UserError

REPO = Path(__file__).resolve().parents[1]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
POKE = 0.5
WD, SIGMA, AMPLITUDE = 9.0, 2.0, 0.05


def run_columns(stop: float = 2.0, dt: float = 1e-3) -> dict[str, np.ndarray]:
    """A poke response with a known first peak at tau = atan(WD / SIGMA) / WD."""
    t = np.arange(0.0, stop, dt)
    tau = np.clip(t - POKE, 0.0, None)
    alpha = AMPLITUDE * np.exp(-SIGMA * tau) * np.sin(WD * tau)
    volts = np.clip(-40.0 * alpha, -10, 10)
    return {
        "t": t,
        "x": -0.1 * (1 - np.exp(-3 * tau)),
        "xdot": -0.3 * np.exp(-3 * tau) * (t >= POKE),
        "alpha": alpha,
        "alpha_measured": np.round(alpha / 0.001) * 0.001,
        "tip": 0.6413 * alpha,
        "voltage_command": -40.0 * alpha,
        "voltage": volts,
        "supervisor_state": np.ones_like(t),
    }


def assert_png(path: Path) -> np.ndarray:
    assert path.is_file() and path.stat().st_size > 1000
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    image = matplotlib.image.imread(path)
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100 and image.shape[2] in (3, 4)
    return image


def test_plot_run_writes_overview_and_one_png_per_quantity(tmp_path):
    paths = plot_run(run_columns(), tmp_path / "plots", title="C(s) = 40", poke_start=POKE, safety_cut_time=1.8)
    assert [p.name for p in paths] == ["run.png", "response.png", "angle.png", "tip.png", "cart.png", "voltage.png"]
    overview = assert_png(paths[0])
    single = assert_png(paths[1])
    assert overview.shape[0] > 2 * single.shape[0]  # four stacked panels
    # The plots are not blank: many distinct colours (lines, legend, markers).
    rgb = (overview[..., :3] * 255).astype(np.uint32)
    assert np.unique(rgb[..., 0] << 16 | rgb[..., 1] << 8 | rgb[..., 2]).size > 50
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == sorted(p.name for p in paths)


def test_plot_run_tolerates_missing_columns(tmp_path):
    cols = {k: v for k, v in run_columns().items() if k in ("t", "alpha_measured", "x")}
    paths = plot_run(cols, tmp_path)
    for path in paths:
        assert_png(path)
    with pytest.raises(ValueError, match="time column"):
        plot_run({"alpha": np.zeros(3)}, tmp_path)


def test_plot_run_into_a_file_path_is_a_user_error(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(UserError, match="cannot create plot folder"):
        plot_run(run_columns(), blocker / "plots")


PLANT = control.tf([5.247, 0.0], np.poly([-16.26, -4.561, 4.843]))


def test_root_locus_png(tmp_path):
    controller = control.tf([30.0, 30.0 * 3.0], [1.0, 62.8]) * control.tf([1.0, 1.0], [1.0, 0.1])
    path = plot_root_locus(0.6413 * controller * PLANT, tmp_path / "rl.png", title="Lp C G")
    assert path == tmp_path / "rl.png"
    assert_png(path)


def test_root_locus_branches_start_at_poles_and_hit_closed_loop_poles():
    num, den = [1.0, 2.0], np.poly([-1.0, -3.0 + 2j, -3.0 - 2j, 4.0]).real
    gains, loci = root_locus_branches(num, den, np.concatenate(([0.0], np.logspace(-3, 3, 200))), max_step=0.05, radius=50)
    assert gains.size > 201  # refined near the fast-moving parts
    np.testing.assert_allclose(np.sort_complex(loci[0]), np.sort_complex(np.roots(den)), atol=1e-9)
    for k, row in zip(gains[::37], loci[::37]):
        expected = np.roots(np.polyadd(den, k * np.asarray(num)))
        np.testing.assert_allclose(np.sort_complex(row), np.sort_complex(expected), atol=1e-6)
    # Branches are continuous where they are drawn (inside the radius): small steps only.
    steps = np.abs(np.diff(loci, axis=0))
    inside = np.minimum(np.abs(loci[:-1]), np.abs(loci[1:])) < 50
    assert steps[inside].max() <= 0.05 + 1e-9


@pytest.mark.parametrize(
    "loop, match",
    [
        (control.tf([1.0, 2.0, 3.0], [1.0, 1.0]), "improper"),
        (control.tf([1.0], [1.0, 1.0], 0.01), "continuous"),
        (control.tf([[[1.0], [1.0]]], [[[1.0, 1.0], [1.0, 2.0]]]), "SISO"),
        ("not a system", "TransferFunction"),
    ],
)
def test_root_locus_rejects_unusable_loops(tmp_path, loop, match):
    with pytest.raises(ValueError, match=match):
        plot_root_locus(loop, tmp_path / "rl.png")
    assert not (tmp_path / "rl.png").exists()


def test_animation_gif_has_frames_at_the_requested_rate(tmp_path):
    cols = run_columns(stop=1.0)
    path = animate_run(cols, tmp_path / "anim" / "rig.gif", Lp=0.6413, poke_start=POKE, fps=20)
    assert path.read_bytes()[:6] in (b"GIF87a", b"GIF89a")
    with Image.open(path) as gif:
        assert gif.n_frames == 20  # 1 s at 20 fps
        assert gif.info["duration"] == 50
        # The poke marker (red) is drawn while the poke is shown, and not long after it.
        gif.seek(int(POKE * 20) + 1)
        poking = np.asarray(gif.convert("RGB")).astype(int)
        gif.seek(gif.n_frames - 1)
        later = np.asarray(gif.convert("RGB")).astype(int)
    red = lambda img: int(np.sum((img[..., 0] > 200) & (img[..., 1] < 60) & (img[..., 2] < 60)))  # noqa: E731
    assert red(poking) > red(later) + 30
    assert [p.name for p in (tmp_path / "anim").iterdir()] == ["rig.gif"]


def test_animation_of_a_fallen_run_and_bad_requests(tmp_path):
    cols = run_columns(stop=0.6)
    cols["alpha"] = np.where(cols["t"] > 0.55, np.nan, np.linspace(0, 1.7, cols["t"].size))
    path = animate_run(cols, tmp_path / "fall.gif", Lp=0.3365, fps=10)
    with Image.open(path) as gif:
        assert gif.n_frames >= 5
    with pytest.raises(UserError, match=r"\.gif or \.mp4"):
        animate_run(cols, tmp_path / "rig.avi", Lp=0.3)
    with pytest.raises(ValueError, match="missing x"):
        animate_run({"t": cols["t"], "alpha": cols["alpha"]}, tmp_path / "a.gif", Lp=0.3)


# ------------------------------------------------------------------------------- example script
SCRIPT = REPO / "examples" / "plot_run.py"


def run_script(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "MPLBACKEND": "Agg"}
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, env=env, timeout=60)


def test_example_script_finds_the_first_peak_in_a_run_mat(tmp_path):
    params = {"poke_start": POKE, "Lp": 0.6413}
    paths = write_results(tmp_path, run_columns(), {"parameters": params, "pendulum": "long"}, {})
    result = run_script(str(paths["mat"]))
    assert result.returncode == 0, result.stderr
    expected_tau = math.atan(WD / SIGMA) / WD
    found = float(re.search(r"peak time \(poke start to first peak\): ([0-9.]+) s", result.stdout).group(1))
    assert found == pytest.approx(expected_tau, abs=2e-3)
    expected_peak = AMPLITUDE * math.exp(-SIGMA * expected_tau) * math.sin(WD * expected_tau)
    degrees = float(re.search(r"first peak: alpha = ([-+0-9.]+) deg", result.stdout).group(1))
    assert degrees == pytest.approx(math.degrees(expected_peak), rel=1e-3)
    assert_png(tmp_path / "my_plot.png")


def test_example_script_is_standalone_and_reports_a_missing_file(tmp_path):
    assert not re.search(r"^\s*(import|from)\s+pendulab", SCRIPT.read_text(), re.MULTILINE)
    result = run_script(str(tmp_path / "nope.mat"))
    assert result.returncode != 0
    assert "does not exist" in result.stderr and "Traceback" not in result.stderr


def _cut_run_columns() -> tuple[dict[str, np.ndarray], float]:
    """A run cut at 1.3 s after which the controller's command runs away to -1000 V."""
    cols = run_columns()
    t = cols["t"]
    cut = 1.3
    after = t >= cut
    cols["voltage_command"] = np.where(after, -1000.0 * np.clip((t - cut) / 0.2, 0, 1), cols["voltage_command"])
    cols["voltage"] = np.where(after, 0.0, cols["voltage"])
    cols["supervisor_state"] = np.where(after, 4.0, 2.0)  # 4 = tripped
    return cols, cut


def _vlines(ax) -> list[float]:
    return [line.get_xdata()[0] for line in ax.get_lines() if len(line.get_xdata()) == 2 and line.get_xdata()[0] == line.get_xdata()[1]]


def test_cut_run_voltage_panel_stays_in_the_amplifier_range_and_marks_the_runaway_command():
    from pendulab.analysis.plots import run_figures

    cols, cut = _cut_run_columns()
    figures = dict(run_figures(cols, poke_start=POKE, voltage_limit=10.0))  # the cut is read from supervisor_state
    overview = figures["run.png"].axes
    assert len(overview) == 5
    voltage = figures["voltage.png"].axes[0]
    lo, hi = voltage.get_ylim()
    assert -12.0 < lo < -10.0 and 10.0 < hi < 12.0  # the amplifier's range, not -1000 V
    assert any(line.get_marker() == "v" for line in voltage.get_lines())  # the runaway is marked at the edge
    assert any("-1e+03 V" in text.get_text() for text in voltage.texts)
    # Poke and cut on every full-length panel; the zoomed response shows the poke (the cut is later).
    for ax in overview[1:]:
        assert sorted(_vlines(ax)) == pytest.approx([POKE, cut]), ax.get_ylabel()
    response = figures["response.png"].axes[0]
    assert _vlines(response) == pytest.approx([POKE])
    lo, hi = response.get_xlim()
    assert lo == pytest.approx(POKE - 0.01) and hi == pytest.approx(POKE + 0.5)
    # The zoomed panel holds the first peak of the response (at atan(WD/SIGMA)/WD after the poke).
    line = response.get_lines()[0]
    peak_time = line.get_xdata()[np.argmax(line.get_ydata())]
    assert peak_time - POKE == pytest.approx(np.arctan(WD / SIGMA) / WD, abs=2e-3)


def test_stable_run_has_no_cut_mark_and_an_unclipped_command():
    from pendulab.analysis.plots import run_figures

    cols = run_columns()
    figures = dict(run_figures(cols, poke_start=POKE))
    for ax in figures["run.png"].axes:
        assert _vlines(ax) == pytest.approx([POKE])
    voltage = figures["voltage.png"].axes[0]
    assert not voltage.texts and not any(line.get_marker() in ("^", "v") for line in voltage.get_lines())
