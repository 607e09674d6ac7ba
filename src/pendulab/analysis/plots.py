"""PNG plots of a run and root-locus pictures, drawn off-screen (matplotlib's Agg renderer).

No window is ever opened and pyplot's global state is not touched: each figure is a
:class:`matplotlib.figure.Figure` with its own Agg canvas, so plotting works on a headless lab PC,
in a test, or inside a long-running program.

Examples
--------
>>> import tempfile, numpy as np
>>> t = np.linspace(0, 3, 301)
>>> cols = {"t": t, "alpha": 0.01 * np.sin(5 * t), "x": 0.02 * t}
>>> [p.name for p in plot_run(cols, tempfile.mkdtemp(), poke_start=1.0)]
['run.png', 'response.png', 'angle.png', 'tip.png', 'cart.png', 'voltage.png']
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from pendulab.analysis.results import atomic_write
from pendulab.errors import UserError
from pendulab.fmu.models.supervisor.config import TRIP_REASONS

DPI = 110


@dataclass(frozen=True)
class _Panel:
    """One quantity of the run: which columns, how to scale them, how to label them."""

    file: str
    title: str
    ylabel: str
    draw: Callable[[Axes, np.ndarray, Mapping[str, np.ndarray]], bool]
    own_xlim: bool = False  # the panel sets its own time range (the zoomed response)


def _series(ax: Axes, t: np.ndarray, cols: Mapping[str, np.ndarray], specs: Sequence[tuple[str, float, str, dict]]) -> bool:
    drawn = False
    for name, scale, label, style in specs:
        if name in cols:
            ax.plot(t, scale * np.asarray(cols[name], dtype=float), label=label, **style)
            drawn = True
    return drawn


_PANELS = (
    _Panel(
        "angle.png",
        "Pendulum angle",
        "angle α (deg)",
        lambda ax, t, c: _series(
            ax,
            t,
            c,
            [
                ("alpha", 180 / np.pi, "α (true)", dict(color="C0", lw=1.6)),
                ("alpha_measured", 180 / np.pi, "α measured (encoder)", dict(color="C1", lw=1.0, drawstyle="steps-post")),
            ],
        ),
    ),
    _Panel(
        "tip.png",
        "Pendulum tip (Lp·α)",
        "tip (cm)",
        lambda ax, t, c: _series(ax, t, c, [("tip", 100.0, "tip = Lp·α", dict(color="C2", lw=1.6))]),
    ),
    _Panel(
        "cart.png",
        "Cart position",
        "cart x (cm)",
        lambda ax, t, c: _series(ax, t, c, [("x", 100.0, "x", dict(color="C4", lw=1.6))]),
    ),
    _Panel(
        "voltage.png",
        "Motor voltage",
        "voltage (V)",
        lambda ax, t, c: _series(
            ax,
            t,
            c,
            [
                ("voltage", 1.0, "applied (after supervisor)", dict(color="C3", lw=1.6)),
                ("voltage_command", 1.0, "command (controller)", dict(color="k", lw=0.9, ls=(0, (4, 3)))),
            ],
        ),
    ),
)

#: The seesaw's angle panel (its runs have ``theta`` instead of ``alpha``, and no tip).
_TILT_PANEL = _Panel(
    "angle.png",
    "Seesaw tilt",
    "tilt θ (deg)",
    lambda ax, t, c: _series(
        ax, t, c,
        [
            ("theta", 180 / np.pi, "θ (true)", dict(color="C0", lw=1.6)),
            ("theta_measured", 180 / np.pi, "θ measured (encoder)", dict(color="C1", lw=1.0, drawstyle="steps-post")),
        ],
    ),
)

#: The amplifier's range (V): the voltage panel is limited to it (PlantParameters.V_max).
DEFAULT_VOLTAGE_LIMIT = 10.0
#: The zoomed response panel: from the poke to this long after it (s), like the old lab's figures.
RESPONSE_WINDOW = 0.5
#: supervisor_state code of a latched trip (pendulab.fmu.models.supervisor.config.TRIPPED).
_TRIPPED = 4
#: Saturated stretches closer than this (s) are shaded as one (a chattering voltage has hundreds).
SATURATION_GAP = 0.02


def saturated_spans(t: np.ndarray, voltage: np.ndarray, limit: float, gap: float = SATURATION_GAP) -> list[tuple[float, float]]:
    """``(start, end)`` times where ``|voltage|`` is at ``limit``, stretches less than ``gap`` apart merged.

    Examples
    --------
    >>> t = np.arange(10) * 0.01
    >>> saturated_spans(t, np.array([0, 10, 10, 0, 0, 0, -10, 0, 0, 0.0]), 10.0)
    [(0.01, 0.02), (0.06, 0.06)]
    """
    at = np.abs(np.nan_to_num(np.asarray(voltage, dtype=float))) >= limit * (1 - 1e-6)
    if not at.any():
        return []
    edges = np.flatnonzero(np.diff(at.astype(np.int8)))
    starts = np.concatenate(([0] if at[0] else [], edges[~at[edges]] + 1)).astype(int)
    ends = np.concatenate((edges[at[edges]], [at.size - 1] if at[-1] else [])).astype(int)
    spans: list[tuple[float, float]] = []
    for i, j in zip(starts, ends):
        if spans and t[i] - spans[-1][1] < gap:
            spans[-1] = (spans[-1][0], float(t[j]))
        else:
            spans.append((float(t[i]), float(t[j])))
    return spans


def plot_run(
    columns: Mapping[str, Any],
    out_dir: str | os.PathLike[str],
    *,
    title: str = "",
    poke_start: float | None = None,
    safety_cut_time: float | None = None,
    voltage_limit: float | None = None,
) -> list[Path]:
    """Plot a run: an overview of stacked panels, and each panel on its own.

    Writes ``run.png`` (the zoomed response, then angle, tip, cart position and voltage over a
    shared time axis) and ``response.png``, ``angle.png``, ``tip.png``, ``cart.png``,
    ``voltage.png`` into ``out_dir``. Angles are in degrees, positions in cm. Columns that are
    missing are left out (a panel with none shows a note).

    * The poke and the safety cut are marked with vertical lines on every panel. Without
      ``safety_cut_time`` the cut is read from the ``supervisor_state`` column (first ``tripped``);
      its reason (angle, track, ...) from the ``trip_reason`` column is in the cut's label.
    * The stretches where the applied voltage is at the amplifier's limit are shaded on every panel.
    * The *response* panel is the angle from the poke to :data:`RESPONSE_WINDOW` after it (the old
      lab's figure); without a poke it is the first half second.
    * The voltage panel is limited to the amplifier's range (``±voltage_limit`` with a margin): a
      command beyond it (a controller running away, often thousands of volts after a cut) is drawn
      clipped, its excursions marked with triangles at the edge and its extreme written in the panel,
      so that the applied voltage stays readable.

    Parameters
    ----------
    columns : mapping of name -> 1-D array
        At least ``t``; normally the run columns (:data:`pendulab.analysis.results.COLUMNS`).
    out_dir : path
        Folder for the PNGs (created if missing).
    title : str
        Title of the overview (e.g. the controller).
    poke_start, safety_cut_time : float, optional
        Times to mark.
    voltage_limit : float, optional
        The amplifier's range (V); default :data:`DEFAULT_VOLTAGE_LIMIT` (the IP02's ``V_max``).

    Returns
    -------
    list of Path
        The PNG files, overview first.
    """
    out = Path(out_dir)
    figures = run_figures(columns, title=title, poke_start=poke_start, safety_cut_time=safety_cut_time, voltage_limit=voltage_limit)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create plot folder {out}: {exc.strerror or exc}; choose another --out") from None
    return [_save(fig, out / name) for name, fig in figures]


def run_figures(
    columns: Mapping[str, Any],
    *,
    title: str = "",
    poke_start: float | None = None,
    safety_cut_time: float | None = None,
    voltage_limit: float | None = None,
) -> list[tuple[str, Figure]]:
    """The figures :func:`plot_run` saves, as ``(file name, Figure)`` pairs, overview first."""
    if "t" not in columns:
        raise ValueError("plot_run needs a time column 't'")
    cols = {k: np.asarray(v, dtype=float).reshape(-1) for k, v in columns.items()}
    t = cols["t"]
    if safety_cut_time is None and "supervisor_state" in cols and cols["supervisor_state"].size == t.size:
        tripped = np.flatnonzero(cols["supervisor_state"] == _TRIPPED)
        safety_cut_time = float(t[tripped[0]]) if tripped.size else None
    limit = float(voltage_limit) if voltage_limit is not None else DEFAULT_VOLTAGE_LIMIT
    cut_label = "safety cut"
    if "trip_reason" in cols and cols["trip_reason"].size == t.size and np.any(cols["trip_reason"] > 0):
        code = int(cols["trip_reason"][np.flatnonzero(cols["trip_reason"] > 0)[0]])
        cut_label = f"safety cut: {TRIP_REASONS.get(code, 'reason ' + str(code))}"
    marks = [(poke_start, "poke", "C3", "--"), (safety_cut_time, cut_label, "k", ":")]
    spans: list[list[float]] = []
    if "supervisor_state" in cols and cols["supervisor_state"].size == t.size:
        # The supervisor's modes (issue 21): swing start and catches as lines, re-centring as shaded spans.
        from pendulab.analysis.modes import mode_metrics

        moments = mode_metrics(t, cols["supervisor_state"], recentring=cols.get("recentring"))
        marks.append((moments["swing_start_s"], "swing-up starts", "C2", "-."))
        marks += [(when, "catch" if k == 0 else None, "C4", "-") for k, when in enumerate(moments["catch_times_s"])]
        spans = moments.get("recentre_intervals_s", [])
    if "voltage" in cols and cols["voltage"].size == t.size:
        marks += [(span, f"voltage at ±{limit:g} V", "C3", "span") for span in saturated_spans(t, cols["voltage"], limit)]
    start = poke_start if poke_start is not None else (float(t[0]) if t.size else 0.0)
    seesaw = "theta" in cols and "alpha" not in cols
    angle = _TILT_PANEL if seesaw else _PANELS[0]
    middle = (angle, _PANELS[2]) if seesaw else _PANELS[:-1]
    panels = (_response_panel(start, angle), *middle, _voltage_panel(limit))

    fig = _figure((9.5, 11.0))
    axes = fig.subplots(len(panels), 1)
    for ax, panel in zip(axes, panels):
        _draw_panel(ax, panel, t, cols, marks, spans)
    for ax in axes[2:]:
        ax.sharex(axes[1])
    for ax in axes[1:-1]:
        ax.tick_params(labelbottom=False)
    axes[0].set_xlabel("time (s)")
    axes[-1].set_xlabel("time (s)")
    if title:
        fig.suptitle(title)
    figures = [("run.png", fig)]

    for panel in panels:
        fig = _figure((9.5, 3.2))
        ax = fig.subplots()
        _draw_panel(ax, panel, t, cols, marks, spans)
        ax.set_title(f"{panel.title}{' - ' + title if title else ''}")
        ax.set_xlabel("time (s)")
        figures.append((panel.file, fig))
    return figures


def _response_panel(start: float, angle: _Panel = _PANELS[0]) -> _Panel:
    """The angle from the poke to RESPONSE_WINDOW after it (x range set by ``_draw_panel``)."""

    def draw(ax: Axes, t: np.ndarray, c: Mapping[str, np.ndarray]) -> bool:
        inside = (t >= start - 0.02 * RESPONSE_WINDOW) & (t <= start + RESPONSE_WINDOW)
        if not inside.any():
            return False
        drawn = angle.draw(ax, t[inside], {k: v[inside] for k, v in c.items() if np.ndim(v) == 1 and len(v) == len(t)})
        ax.set_xlim(max(float(t[0]), start - 0.02 * RESPONSE_WINDOW), start + RESPONSE_WINDOW)
        return drawn

    return _Panel("response.png", f"Response to the poke (first {RESPONSE_WINDOW:g} s)", angle.ylabel, draw, own_xlim=True)


def _voltage_panel(limit: float) -> _Panel:
    """Applied voltage and command, limited to the amplifier's range; a runaway command is marked."""
    edge = 1.15 * limit

    def draw(ax: Axes, t: np.ndarray, c: Mapping[str, np.ndarray]) -> bool:
        drawn = _series(ax, t, c, [("voltage", 1.0, "applied (after supervisor)", dict(color="C3", lw=1.6))])
        command = c.get("voltage_command")
        if command is not None:
            finite = np.where(np.isfinite(command), command, 0.0)
            ax.plot(t, np.clip(finite, -edge, edge), color="k", lw=0.9, ls=(0, (4, 3)), label="command (controller)")
            beyond = np.abs(finite) > edge
            if beyond.any():
                # Mark a few points of each excursion at the panel's edge instead of scaling to them.
                marks = np.flatnonzero(beyond)[:: max(1, int(beyond.sum()) // 40)]
                label = f"command beyond ±{limit:g} V (not to scale)"
                for sign, marker in ((1, "^"), (-1, "v")):
                    side = marks[np.sign(finite[marks]) == sign]
                    if side.size:
                        ax.plot(t[side], np.full(side.size, sign * edge * 0.97), ls="none", marker=marker, ms=5, color="k", label=label)
                        label = None
                worst = finite[np.argmax(np.abs(finite))]
                first = float(t[np.argmax(beyond)])
                ax.text(0.99, 0.04, f"command beyond the range (first at t = {first:.3g} s), extreme {worst:.3g} V",
                        transform=ax.transAxes, ha="right", va="bottom", fontsize="small",
                        bbox=dict(boxstyle="round", fc="white", ec="0.6", alpha=0.9))
            drawn = True
        ax.axhspan(limit, edge, color="0.85", zorder=0)
        ax.axhspan(-edge, -limit, color="0.85", zorder=0)
        ax.set_ylim(-edge, edge)
        return drawn

    return _Panel("voltage.png", f"Motor voltage (amplifier range ±{limit:g} V)", "voltage (V)", draw)


def _draw_panel(ax: Axes, panel: _Panel, t: np.ndarray, cols: Mapping[str, np.ndarray], marks: list,
                spans: list | None = None) -> None:
    drawn = panel.draw(ax, t, cols)
    for k, (start, end) in enumerate(spans or []):
        ax.axvspan(start, end, color="C9", alpha=0.15, lw=0, label="re-centring acts" if k == 0 else None)
    if not drawn:
        ax.text(0.5, 0.5, "not logged in this run", transform=ax.transAxes, ha="center", va="center", color="0.5")
    lo, hi = ax.get_xlim() if panel.own_xlim else (t[0], t[-1]) if t.size else (0.0, 1.0)
    spanned = False
    for when, label, color, style in marks:
        if style == "span":  # a saturated stretch: shaded, labelled once
            if not panel.own_xlim or (when[1] >= lo and when[0] <= hi):
                ax.axvspan(when[0], when[1], color=color, alpha=0.15, lw=0, label=None if spanned else label)
                spanned = True
        elif when is not None and (not panel.own_xlim or lo <= when <= hi):
            ax.axvline(when, color=color, ls=style, lw=1.0, label=label)
    ax.set_ylabel(panel.ylabel)
    ax.grid(True, alpha=0.3)
    if t.size and not panel.own_xlim:
        ax.set_xlim(t[0], t[-1])
    if drawn:
        # Beside the panel, never over the curves.
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False, borderaxespad=0)


def _figure(size: tuple[float, float]) -> Figure:
    fig = Figure(figsize=size, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> Path:
    try:
        return atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=DPI))
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}; check the folder's permissions") from None


# ------------------------------------------------------------------------------------ root locus
def root_locus_branches(
    num: Sequence[float],
    den: Sequence[float],
    gains: np.ndarray,
    *,
    max_step: float | None = None,
    radius: float = np.inf,
    refinements: int = 12,
) -> tuple[np.ndarray, np.ndarray]:
    """Closed-loop poles (roots of ``den + k num``) over gains, sorted into continuous branches.

    Parameters
    ----------
    num, den : sequence of float
        Open-loop numerator and denominator coefficients, highest power first (proper loop).
    gains : array
        Increasing gains to start from.
    max_step : float, optional
        Where a branch moves farther than this between two gains (near break-away points, where
        poles move like the square root of the gain), gains are inserted in between, up to
        ``refinements`` times; only where a branch is within ``radius`` of the origin (the part
        that is drawn).

    Returns
    -------
    gains : array (m,)
        The gains used (the given ones plus any inserted).
    loci : array (m, degree of den), complex
        Row ``i`` holds the poles at ``gains[i]``; column ``j`` follows one branch.
    """
    num = np.trim_zeros(np.atleast_1d(np.asarray(num, dtype=float)), "f")
    den = np.trim_zeros(np.atleast_1d(np.asarray(den, dtype=float)), "f")
    padded = np.concatenate((np.zeros(den.size - num.size), num))
    gains = np.asarray(gains, dtype=float)
    roots = _roots_batch(den, padded, gains)
    loci = _track(roots)
    for _ in range(refinements if max_step else 0):
        step = np.abs(np.diff(loci, axis=0))
        visible = np.minimum(np.abs(loci[:-1]), np.abs(loci[1:])) < radius
        coarse = np.flatnonzero(((step > max_step) & visible).any(axis=1))
        if coarse.size == 0:
            break
        lo, hi = gains[coarse], gains[coarse + 1]
        middle = np.where(lo > 0, np.sqrt(lo * hi), 0.5 * (lo + hi))
        order = np.argsort(np.concatenate((gains, middle)), kind="stable")
        gains = np.concatenate((gains, middle))[order]
        roots = np.concatenate((roots, _roots_batch(den, padded, middle)))[order]
        loci = _track(roots)
    return gains, loci


def _roots_batch(den: np.ndarray, num: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """Roots of ``den + k num`` for many gains at once (eigenvalues of stacked companion matrices)."""
    poly = den[None, :] + gains[:, None] * num[None, :]
    lead = poly[:, :1]
    lead = np.where(np.abs(lead) < 1e-12 * np.abs(den[0]), 1e-12 * den[0], lead)  # degree drop: nudge
    n = den.size - 1
    companion = np.zeros((gains.size, n, n))
    companion[:, 0, :] = -poly[:, 1:] / lead
    companion[:, np.arange(1, n), np.arange(n - 1)] = 1.0
    return np.linalg.eigvals(companion)


def _track(roots: Sequence[np.ndarray]) -> np.ndarray:
    """Order each row of roots so that column j is the continuation of column j of the row before."""
    from scipy.optimize import linear_sum_assignment

    loci = np.empty((len(roots), roots[0].size), dtype=complex)
    previous = None
    for i, r in enumerate(roots):
        if previous is not None:
            _, order = linear_sum_assignment(np.abs(previous[:, None] - r[None, :]))
            r = r[order]
        loci[i] = previous = r
    return loci


@dataclass(frozen=True)
class RootLocus:
    """What a root-locus plot shows: branches, open-loop poles and zeros, the closed-loop poles at gain 1, a view.

    ``loci[:, j]`` is branch ``j`` over the gains; ``view`` is ``(re_lo, re_hi, half)``: the real-axis
    range and the half-height of the imaginary range that frame every marked point.
    """

    gains: np.ndarray
    loci: np.ndarray
    poles: np.ndarray
    zeros: np.ndarray
    closed: np.ndarray
    view: tuple[float, float, float]

    @property
    def stable(self) -> bool:
        return bool(np.all(self.closed.real < 0))


def root_locus(loop_tf: Any) -> RootLocus:
    """Root locus of an open loop ``L(s)`` under negative feedback ``1 + k L(s) = 0`` (see :func:`plot_root_locus`)."""
    num, den = _siso_polynomials(loop_tf)
    poles, zeros = np.roots(den), np.roots(num) if num.size > 1 else np.array([], dtype=complex)
    closed = np.roots(den + np.concatenate((np.zeros(den.size - num.size), num)))

    # Gains from "poles barely moved" to "poles near the zeros or far out": scaled by the gain at
    # which |k num| matches |den| at the loop's typical frequency.
    magnitudes = np.abs(np.concatenate((poles, zeros)))
    magnitudes = magnitudes[magnitudes > 1e-9]
    omega = float(np.exp(np.mean(np.log(magnitudes)))) if magnitudes.size else 1.0
    k0 = abs(np.polyval(den, 1j * omega)) / max(abs(np.polyval(num, 1j * omega)), 1e-300)
    lo, hi = np.log10(min(k0, 1.0)) - 4, np.log10(max(k0, 1.0)) + 4
    gains = np.unique(np.concatenate(([0.0], np.logspace(lo, hi, 600), [1.0])))

    # View: every marked point with a margin; the branches that run off to infinity are clipped.
    points = np.concatenate((poles, zeros, closed))
    re_lo, re_hi = min(points.real.min(), 0.0), max(points.real.max(), 0.0)
    width = max(re_hi - re_lo, 1e-6)
    re_lo, re_hi = re_lo - 0.12 * width, re_hi + 0.12 * width
    half = max(1.25 * np.abs(points.imag).max(), 0.4 * (re_hi - re_lo))
    view = max(re_hi - re_lo, 2 * half)
    radius = 1.5 * max(abs(re_lo), abs(re_hi), half)
    gains, loci = root_locus_branches(num, den, gains, max_step=0.004 * view, radius=radius)
    return RootLocus(gains, loci, poles, zeros, closed, (float(re_lo), float(re_hi), float(half)))


def plot_root_locus(loop_tf: Any, path: str | os.PathLike[str], *, title: str = "") -> Path:
    """PNG of the root locus of an open loop ``L(s)`` under negative feedback ``1 + k L(s) = 0``.

    Marks the open-loop poles (x), zeros (o), the imaginary axis, and the closed-loop poles at the
    loop's own gain ``k = 1`` (filled squares), which are the poles of the designed loop.

    Parameters
    ----------
    loop_tf : control.TransferFunction
        SISO, continuous time, proper; e.g. ``Lp * C(s) * G(s)`` (SPEC §3).
    path : path
        The PNG file.
    title : str
        Figure title.

    Examples
    --------
    >>> import control, tempfile, os
    >>> L = control.tf([5.0, 5.0], [1.0, 3.0, -4.0, 0.5])
    >>> plot_root_locus(L, os.path.join(tempfile.mkdtemp(), "rl.png")).name
    'rl.png'
    """
    rl = root_locus(loop_tf)
    loci, poles, zeros, closed = rl.loci, rl.poles, rl.zeros, rl.closed
    re_lo, re_hi, half = rl.view

    fig = _figure((7.0, 5.6))
    ax = fig.subplots()
    ax.axvline(0.0, color="k", lw=1.0, label="imaginary axis")
    ax.axhline(0.0, color="0.6", lw=0.6)
    for j in range(loci.shape[1]):
        ax.plot(loci[:, j].real, loci[:, j].imag, color="C0", lw=1.5, label="root locus" if j == 0 else None)
    ax.plot(poles.real, poles.imag, "x", color="C3", ms=10, mew=2.2, label="open-loop poles")
    if zeros.size:
        ax.plot(zeros.real, zeros.imag, "o", mfc="none", mec="C2", ms=10, mew=2.0, label="open-loop zeros")
    stable = bool(np.all(closed.real < 0))
    ax.plot(
        closed.real,
        closed.imag,
        "s",
        color="C1" if stable else "C3",
        ms=7,
        mec="k",
        label="closed-loop poles at gain 1" + ("" if stable else " (UNSTABLE)"),
    )

    ax.set_xlim(re_lo, re_hi)
    ax.set_ylim(-half, half)
    ax.set_xlabel("real axis σ (1/s)")
    ax.set_ylabel("imaginary axis ω (rad/s)")
    ax.set_title(title or "Root locus of the loop L(s)")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small", framealpha=0.85)
    return _save(fig, Path(path))


def _siso_polynomials(loop_tf: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        ninputs, noutputs, dt = loop_tf.ninputs, loop_tf.noutputs, loop_tf.dt
        num = np.asarray(loop_tf.num[0][0], dtype=float)
        den = np.asarray(loop_tf.den[0][0], dtype=float)
    except (AttributeError, IndexError, TypeError) as exc:
        raise ValueError(f"plot_root_locus needs a control.TransferFunction ({exc})") from None
    if ninputs != 1 or noutputs != 1:
        raise ValueError(f"the loop must be SISO; it has {ninputs} inputs and {noutputs} outputs")
    if dt not in (0, None):
        raise ValueError("the root locus here is for continuous-time loops; give L(s), not a discrete L(z)")
    num = np.trim_zeros(np.atleast_1d(num), "f")
    den = np.trim_zeros(np.atleast_1d(den), "f")
    if den.size < 2:
        raise ValueError("the loop has no poles: nothing to draw a root locus of")
    if num.size == 0:
        raise ValueError("the loop is zero: nothing to draw a root locus of")
    if num.size > den.size:
        raise ValueError("the loop is improper (more zeros than poles); a controller must be proper")
    return num, den
