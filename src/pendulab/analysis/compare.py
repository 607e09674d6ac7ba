"""Runs side by side (rig against simulation): aligned at the poke, the old lab's table, an overlay plot.

A seesaw run (its tilt ``theta`` where the pendulum's runs have ``alpha``) is compared by its tilt, aligned at
its tap; runs of the two plants are not compared with each other.

The poke's onset in a measured angle (:func:`detect_poke`) is found here too: the lab's results and
the comparison of runs that do not say when their poke came both use it.

Examples
--------
>>> # skipped: needs a simulated run and a rig run in runs/ (compare_runs has one that runs)
>>> runs = [load_compared(p) for p in ("runs/sim", "runs/rig")]      # doctest: +SKIP
>>> print(table_text(runs))                                           # doctest: +SKIP
>>> nrmse(runs[1], runs[0], "alpha", window=1.0)                      # doctest: +SKIP
0.031
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from pendulab.errors import UserError

#: The old lab's comparison table: metrics.json key -> (label, unit, scale).
TABLE = (
    ("natural_frequency_rad_s", "natural frequency", "rad/s", 1.0),
    ("peak_time_s", "peak time", "s", 1.0),
    ("settling_time_s", "settling time", "s", 1.0),
    ("overshoot_percent", "overshoot", "%", 1.0),
    ("final_value_rad", "final value", "rad", 1.0),
    ("cart_speed_change_m_s", "cart speed change", "m/s", 1.0),
)
PANELS = (("alpha", "angle (rad)"), ("tip", "tip (m)"), ("x", "cart (m)"), ("voltage", "voltage (V)"))
#: The seesaw's panels: its tilt, the cart, the voltage (no tip).
SEESAW_PANELS = (("theta", "tilt (rad)"), ("x", "cart (m)"), ("voltage", "voltage (V)"))


@dataclass
class ComparedRun:
    """One run: its columns, where its poke (the seesaw's tap) starts, its metrics, a label, its angle column."""

    label: str
    columns: dict[str, np.ndarray]
    poke_start: float
    metrics: dict[str, Any]
    source: str
    angle: str = "alpha"  # "theta": a seesaw run

    @property
    def seesaw(self) -> bool:
        return self.angle == "theta"

    def aligned(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """``(t - poke_start, column)``."""
        return self.columns["t"] - self.poke_start, self.columns[name]


def _is_old_lab_folder(path: Path) -> bool:
    return path.is_dir() and not (path / "run.mat").exists() and not (path / "run.csv").exists() and any(path.glob("*.mat"))


def load_compared(path: str | Path, *, Lp: float | None = None, q_alpha: float = 2 * np.pi / 4096) -> ComparedRun:
    """A run folder (``pendulab simulate``/``lab``), a run file, or a folder of the old lab's logs.

    A seesaw run is aligned at its tap (the parameters' ``tap_start``, or the rig's detected one) and measured by
    its tilt (``q_alpha`` is then the tilt encoder's step unless the run's parameters say another).
    """
    from pendulab.analysis.results import is_seesaw_run
    from pendulab.analysis.verdict import Limits, assess, was_cut_before_poke

    path = Path(path)
    if not path.exists():
        raise UserError(f"run {path} does not exist; give a run folder (from 'pendulab simulate' or 'pendulab lab'), its run.mat, or a folder of the old lab's logs")
    metrics: dict[str, Any] = {}
    if _is_old_lab_folder(path):
        try:
            from pendulab.calibration.logs import read_old_lab_folder
        except ImportError:
            raise UserError(f"{path} looks like a folder of the old lab's logs, which this pendulab cannot read yet") from None
        raw = read_old_lab_folder(path)
        length = Lp or 0.6413
        columns = {k: np.asarray(v, dtype=float) for k, v in raw.items()}
        columns.setdefault("tip", length * columns["alpha"])
        columns.setdefault("voltage", np.zeros_like(columns["t"]))
        columns.setdefault("x", np.zeros_like(columns["t"]))
        meta: dict[str, Any] = {"source": "old lab"}
        source = "old lab"
    else:
        from pendulab.analysis.results import read_run

        columns, meta = read_run(path)
        folder = path if path.is_dir() else path.parent
        if (folder / "metrics.json").is_file():
            try:
                metrics = json.loads((folder / "metrics.json").read_text())
            except (OSError, ValueError) as exc:
                raise UserError(f"cannot read {folder / 'metrics.json'}: {exc}; rewrite it or remove it") from None
        source = str(meta.get("source", "simulation"))
    angle = "theta" if is_seesaw_run(columns) else "alpha"
    params = meta.get("parameters") if isinstance(meta.get("parameters"), Mapping) else None
    if angle == "theta":
        from pendulab.model.seesaw import SEESAW_COUNT

        q_alpha = float(np.ravel(params["q_theta"])[0]) if params and "q_theta" in params else SEESAW_COUNT
        q_alpha = q_alpha or SEESAW_COUNT  # (a run without quantization: the encoder's step for finding the tap)
    for name in ("t", angle, "x"):
        bad = np.flatnonzero(~np.isfinite(np.asarray(columns[name], dtype=float)))
        if bad.size:
            # Said as it is: an aligned comparison of such a run would report "no poke found".
            where = f"t = {columns['t'][bad[0]]:.4g} s" if name != "t" else f"sample {bad[0] + 1}"
            raise UserError(f"run {path}: {name} is not a number (NaN or inf) from {where} on ({bad.size} samples); "
                            "the file is damaged or was written by a failed run: compare an intact run")
    poke = None
    start = "tap_start" if angle == "theta" else "poke_start"
    if source != "rig" and params and start in params and source != "old lab":
        poke = float(np.ravel(params[start])[0])
    if was_cut_before_poke(metrics):
        raise UserError(f"run {path} was cut before the poke ({metrics['verdict']['headline']}); a comparison aligns runs at their poke")
    if poke is None and metrics.get("poke_start_detected_s") is not None:
        poke = float(metrics["poke_start_detected_s"])
    if poke is None:
        poke = detect_poke(columns["t"], columns[angle], q_alpha=q_alpha, long_pulse=angle == "theta")
    if poke is None:
        what = "tap in the tilt" if angle == "theta" else "poke in the angle"
        raise UserError(f"no {what} of {path}; a comparison aligns runs at their {what.split()[0]}")
    if not metrics and angle == "theta":  # a seesaw run without metrics.json: judged as a seesaw, with its tilt's step
        from pendulab.cosim.seesaw import verdict_limits

        metrics, _ = assess(columns, poke_start=poke, limits=replace(verdict_limits(), q_alpha=q_alpha), plant="seesaw")
    if not metrics:  # a run without metrics.json (the old lab's logs): measured and judged as any run
        metrics, _ = assess(columns, poke_start=poke, limits=Limits(q_alpha=q_alpha))
    name = path.name if path.is_dir() else f"{path.parent.name}/{path.name}"
    label = name if name == source else f"{name} ({source})"
    return ComparedRun(label, columns, poke, metrics, source, angle)


def nrmse(run: ComparedRun, reference: ComparedRun, name: str | None = None, *, window: float = 1.0) -> float:
    """RMS difference of ``name`` (default the reference's angle: ``alpha``, the seesaw's ``theta``) over ``window`` s
    after the poke, divided by the reference's range there."""
    name = name or reference.angle
    t_ref, y_ref = reference.aligned(name)
    t_run, y_run = run.aligned(name)
    keep = (t_ref >= 0) & (t_ref <= window) & (t_ref <= t_run[-1])
    if keep.sum() < 10:
        raise UserError(f"{run.label} and {reference.label} overlap for less than 10 samples after the poke")
    y = np.interp(t_ref[keep], t_run, y_run)
    span = float(np.ptp(y_ref[keep]))
    if span == 0:
        raise UserError(f"{reference.label} does not move after its poke; nothing to compare")
    return float(np.sqrt(np.mean((y - y_ref[keep]) ** 2)) / span)


#: A poke's speed, in encoder steps per 10 ms, at least (150 rad/s^2 for 5 ms: 6 steps of the 4096-count encoder).
POKE_STEPS = 3


def detect_poke(t: np.ndarray, alpha: np.ndarray, *, q_alpha: float, after: float | None = None,
                before: float | None = None, long_pulse: bool = False) -> float | None:
    """Onset of the poke in a measured angle: where the angular velocity jumps.

    A poke is a short pulse of angular acceleration, so the angle's speed (a central difference over
    10 ms, which averages the encoder steps away) jumps within a few milliseconds to the largest value
    of the run before any cut. The onset is the first sample where the speed reaches half that value
    (at most a few ms after the true start for a pulse of 5 ms). None when nothing moves by more than
    :data:`POKE_STEPS` encoder steps per difference window.

    ``long_pulse``: the seesaw's tap lasts 0.1 s, along which the speed rises: half its peak comes some 60 ms
    after the onset. The onset is then where the angle leaves its rest as a constant acceleration does,
    ``(theta - rest) = a (t - onset)^2 / 2``: the square root of the departure is a straight line in time,
    fitted over the early rise and extrapolated to zero (:func:`pulse_onset`).
    """
    t = np.asarray(t, dtype=float)
    alpha = np.asarray(alpha, dtype=float)
    mask = np.ones_like(t, dtype=bool)
    if after is not None:
        mask &= t >= after
    if before is not None:
        mask &= t < before
    idx = np.flatnonzero(mask)
    if idx.size < 30:
        return None
    ts, seg = t[idx], alpha[idx]
    h = float(np.median(np.diff(ts)))
    w = max(1, int(round(0.005 / h)))
    speed = np.abs(seg[2 * w:] - seg[: -2 * w]) / (ts[2 * w:] - ts[: -2 * w])
    # A poke moves the angle by several encoder steps per difference window; the controller's catch after
    # the hand let go (a held angle of half a degree) stays within two.
    if speed.size == 0 or speed.max() < POKE_STEPS * max(q_alpha, 1e-9) / (2 * w * h):
        return None
    first = int(np.argmax(speed >= 0.5 * speed.max()))
    half = float(ts[first + w])
    if long_pulse:
        onset = pulse_onset(ts, seg, half, q_alpha=q_alpha)
        return half if onset is None else onset
    return half


def pulse_onset(t: np.ndarray, angle: np.ndarray, half: float, *, q_alpha: float, span: float = 0.15) -> float | None:
    """Onset of a pulse of angular acceleration whose speed reaches half its peak at ``half`` (s).

    The rest is the angle's median over 0.2 s ending ``span`` before ``half``; the departure from it grows as
    ``a (t - onset)^2 / 2`` while the pulse acts, so ``sqrt(departure)`` is fitted by a straight line over the samples
    in the ``span`` before ``half`` that have left the rest by 4 encoder steps and not yet by a quarter of the
    response's peak, and extrapolated to zero. None when that leaves fewer than 5 samples or no onset within ``span``.

    Examples
    --------
    >>> t = np.arange(0.0, 2.0, 0.001)
    >>> theta = np.where(t > 1.0, 0.5 * 3.3 * (t - 1.0) ** 2, 0.0)      # 3.3 rad/s^2 from t = 1 s
    >>> round(pulse_onset(t, theta, 1.05, q_alpha=5e-4), 3)
    1.0
    """
    rest_window = (t > half - span - 0.2) & (t <= half - span)
    if not rest_window.any():
        return None
    departure = np.abs(angle - np.median(angle[rest_window]))
    after = (t > half) & (t < half + 0.4)
    if not after.any():
        return None
    use = (t > half - span) & (t <= half) & (departure >= 4 * q_alpha) & (departure <= 0.25 * departure[after].max())
    if use.sum() < 5:
        return None
    slope, intercept = np.polyfit(t[use], np.sqrt(departure[use]), 1)
    if slope <= 0:
        return None
    onset = float(-intercept / slope)
    return onset if half - span <= onset <= half else None


def _fmt(value: Any, unit: str) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "n/a"
    return f"{value:.4g} {unit}"


def _outcome(metrics: Mapping[str, Any]) -> str:
    """The verdict's outcome and warnings, short: ``balanced``, ``balanced (drift)``, ``cut (track limit)``."""
    verdict = metrics.get("verdict")
    if not isinstance(verdict, Mapping):
        return "n/a"
    kinds = [w.get("kind", "") for w in verdict.get("warnings") or ()]
    detail = verdict.get("cut_reason") if verdict.get("outcome") in ("cut", "fell") and verdict.get("cut_reason") else ", ".join(kinds)
    return f"{verdict.get('outcome')}" + (f" ({detail})" if detail else "")


def table_text(runs: list[ComparedRun]) -> str:
    """The old lab's table as text: one row per metric, one column per run."""
    width = max(22, *(len(r.label) + 2 for r in runs))
    lines = ["".ljust(20) + "".join(r.label.rjust(width) for r in runs)]
    lines.append("verdict".ljust(20) + "".join(_outcome(r.metrics).rjust(width) for r in runs))
    for key, label, unit, _ in TABLE:
        lines.append(label.ljust(20) + "".join(_fmt(r.metrics.get(key), unit).rjust(width) for r in runs))
    if len(runs) >= 2:
        lines.append("angle NRMSE vs first".ljust(20) + "".join(
            ("-" if i == 0 else f"{100 * nrmse(r, runs[0]):.1f} %").rjust(width) for i, r in enumerate(runs)))
    return "\n".join(lines)


def plot_comparison(runs: list[ComparedRun], path: Path, *, window: tuple[float, float] = (-0.2, 2.0)) -> Path:
    """Angle, tip, cart and voltage overlaid (aligned at the poke) above the table; a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pendulab.analysis.results import atomic_write

    panels = SEESAW_PANELS if runs[0].seesaw else PANELS
    kick = "tap" if runs[0].seesaw else "poke"
    fig = plt.figure(figsize=(10, 11))
    grid = fig.add_gridspec(len(panels) + 1, 1, height_ratios=[1] * len(panels) + [0.9])
    for k, (name, ylabel) in enumerate(panels):
        ax = fig.add_subplot(grid[k])
        for run in runs:
            t, y = run.aligned(name)
            keep = (t >= window[0]) & (t <= window[1])
            ax.plot(t[keep], y[keep], label=run.label, lw=1.2)
        ax.axvline(0.0, color="k", ls=":", lw=0.8)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        if name == "voltage":
            ax.set_ylim(-11, 11)  # the amplifier's range: a runaway command does not flatten the plot
        if k == 0:
            ax.legend(loc="upper right", fontsize=8)
            ax.set_title(f"aligned at the {kick} (t = 0)")
    ax.set_xlabel(f"time since the {kick} (s)")
    table_ax = fig.add_subplot(grid[len(panels)])
    table_ax.axis("off")
    cells = [[_fmt(r.metrics.get(key), unit) for r in runs] for key, _, unit, _ in TABLE]
    table = table_ax.table(cellText=cells, rowLabels=[label for _, label, _, _ in TABLE], colLabels=[r.label for r in runs], loc="center")
    table.auto_set_font_size(False)
    table.set_fontsize(8)
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=90))
    plt.close(fig)
    return path


def compare_runs(paths: list[str | Path], out_dir: Path, *, Lp: float | None = None) -> tuple[str, list[Path]]:
    """Runs side by side, aligned at the poke: the old lab's table and a plot (``pendulab compare``).

    Parameters
    ----------
    paths : list of path
        Run folders (``run.mat``) or folders of the old lab's logs.
    out_dir : path
        Where ``comparison.txt`` and ``comparison.png`` are written.
    Lp : float, optional
        Pendulum length for runs that do not say (old-lab logs).

    Returns
    -------
    (str, list of Path)
        The table's text and the files written.

    Examples
    --------
    >>> import tempfile, pendulab
    >>> folder = Path(tempfile.mkdtemp())
    >>> for delay in (0, 2):
    ...     spec = pendulab.RunSpec(pendulab.demo_controller(), timing=pendulab.Timing(stop_time=2.0, delay=delay))
    ...     _ = pendulab.simulate(spec).write(folder / f"delay{delay}")
    >>> text, files = compare_runs([folder / "delay0", folder / "delay2"], folder / "comparison")
    >>> [f.name for f in files]
    ['comparison.txt', 'comparison.png']
    """
    from pendulab.analysis.results import atomic_write

    runs = [load_compared(p, Lp=Lp) for p in paths]
    if len({run.seesaw for run in runs}) > 1:
        kinds = ", ".join(f"{run.label}: {'seesaw' if run.seesaw else 'pendulum'}" for run in runs)
        raise UserError(f"these runs are of different plants ({kinds}); compare seesaw runs with seesaw runs")
    text = table_text(runs)
    out_dir.mkdir(parents=True, exist_ok=True)
    txt = atomic_write(out_dir / "comparison.txt", lambda f: f.write((text + "\n").encode()))
    png = plot_comparison(runs, out_dir / "comparison.png")
    return text, [txt, png]


def compare_with_simulation(out_dir: Path, spec: Any, *, metrics: Mapping[str, Any]) -> str:
    """``pendulab lab --compare``: the simulation of ``spec`` (a :class:`~pendulab.spec.RunSpec` at the rig's delay)
    into ``out_dir/simulation``, then the comparison."""
    from pendulab.simulation import simulate

    sim_dir = out_dir / "simulation"
    result = simulate(spec, meta={"source": "simulation", "pendulum": "", "calibration": ""})
    result.write(sim_dir)
    text, _ = compare_runs([sim_dir, out_dir], out_dir, Lp=getattr(result.spec.parameters(), "Lp", None))
    print(text)
    return text
