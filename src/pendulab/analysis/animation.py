"""An animation of the rig during a run: the cart on its track, the pendulum, the poke.

Drawn off-screen with matplotlib (Agg) and written as a GIF with
:class:`matplotlib.animation.PillowWriter` (Pillow comes with matplotlib), or as an MP4 when the
path ends in ``.mp4`` and ``ffmpeg`` is installed.

Conventions (SPEC §2): ``x`` positive to the right; ``alpha`` measured from upright, positive
counter-clockwise, so a positive angle leans the pendulum toward ``-x``.

Examples
--------
>>> import tempfile, os, numpy as np
>>> t = np.linspace(0.0, 0.4, 41)
>>> cols = {"t": t, "x": 0.05 * t, "alpha": 0.1 * np.sin(8 * t)}
>>> path = animate_run(cols, os.path.join(tempfile.mkdtemp(), "rig.gif"), Lp=0.64, poke_start=0.1, fps=10)
>>> path.name
'rig.gif'
"""

from __future__ import annotations

import io
import math
import os
import shutil
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from matplotlib import animation
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import FancyArrowPatch, Rectangle
from PIL import Image

from pendulab.analysis.results import create_temporary
from pendulab.errors import UserError

CART_WIDTH = 0.10  # m, drawing only
CART_HEIGHT = 0.05  # m
TRACK_LIMIT = 0.40  # m, the supervisor's default x_max (SPEC §5), drawn as the track's end marks
POKE_SHOWN = 0.2  # s the poke marker stays visible


def animate_run(
    columns: Mapping[str, Any],
    path: str | os.PathLike[str],
    *,
    Lp: float,
    poke_start: float | None = None,
    fps: int = 25,
    dpi: int = 80,
) -> Path:
    """Write an animation of the run (GIF, or MP4 if ``path`` ends in ``.mp4``).

    Parameters
    ----------
    columns : mapping of name -> 1-D array
        ``t``, ``x`` and ``alpha`` (or ``alpha_measured`` when the true angle is not logged).
    path : path
        Output file; written atomically.
    Lp : float
        Pendulum length, pivot to tip (m); 0 draws the cart alone.
    poke_start : float, optional
        Time of the poke: a red arrow at the tip and "poke" for 0.2 s from then.
    fps : int
        Frames per second of the animation; the run is resampled to it (real-time playback).
    dpi : int
        Resolution (the figure is 6.4 x 3.2 in: 512 x 256 pixels at 80 dpi).

    Returns
    -------
    Path
        ``path``.
    """
    t, x, alpha = _signals(columns)
    if not (math.isfinite(Lp) and Lp >= 0):
        raise ValueError(f"Lp={Lp} must be a length >= 0 m")
    if not 1 <= fps <= 60:
        raise ValueError(f"fps={fps} must be between 1 and 60")
    path = Path(path)
    writer = _writer(path, fps)

    frames = np.arange(t[0], t[-1] + 1e-9, 1.0 / fps)
    xf = np.interp(frames, t, x)
    af = np.interp(frames, t, alpha)
    poke_sign = _poke_direction(t, alpha, poke_start)

    fig = Figure(figsize=(6.4, 3.2), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.02, 0.04, 0.96, 0.92))
    reach = Lp + CART_WIDTH
    # Symmetric about the track centre, wide enough for the track limits and the pendulum.
    right = max(TRACK_LIMIT + 0.05, float(np.abs(xf).max()) + reach)
    left = -right
    ax.set_xlim(left, right)
    ax.set_ylim(-0.12 - 0.3 * Lp, CART_HEIGHT + 1.15 * Lp + 0.05)
    ax.set_aspect("equal", adjustable="box")
    ax.set_axis_off()

    # Static scene: the track, its limits and the centre mark.
    ax.plot([left, right], [-0.005, -0.005], color="0.35", lw=3, solid_capstyle="butt")
    for end in (-TRACK_LIMIT, TRACK_LIMIT):
        ax.plot([end, end], [-0.04, 0.03], color="C3", lw=1.5)
    ax.plot([0, 0], [-0.03, -0.005], color="0.35", lw=1)
    ax.text(TRACK_LIMIT, -0.06, "limit", color="C3", ha="center", va="top", fontsize=7)
    ax.text(-TRACK_LIMIT, -0.06, "limit", color="C3", ha="center", va="top", fontsize=7)

    # Moving parts.
    cart = Rectangle((0, 0), CART_WIDTH, CART_HEIGHT, facecolor="C0", edgecolor="k", lw=1)
    ax.add_patch(cart)
    (rod,) = ax.plot([], [], color="C1", lw=4, solid_capstyle="round")
    (pivot,) = ax.plot([], [], "o", color="k", ms=4)
    clock = ax.text(0.01, 0.97, "", transform=ax.transAxes, va="top", family="monospace", fontsize=9)
    poke_arrow = FancyArrowPatch((0, 0), (0, 0), arrowstyle="-|>", mutation_scale=18, color="red", lw=2.5)
    ax.add_patch(poke_arrow)
    poke_text = ax.text(0, 0, "poke", color="red", fontsize=11, fontweight="bold", ha="center", va="bottom")

    def draw(i: int) -> None:
        xc, a = xf[i], af[i]
        cart.set_x(xc - CART_WIDTH / 2)
        px, py = xc, CART_HEIGHT
        tip = (px - Lp * math.sin(a), py + Lp * math.cos(a))
        rod.set_data([px, tip[0]], [py, tip[1]])
        pivot.set_data([px], [py])
        clock.set_text(f"t = {frames[i]:6.3f} s   x = {100 * xc:+6.1f} cm   α = {math.degrees(a):+6.2f}°")
        poking = poke_start is not None and poke_start <= frames[i] < poke_start + POKE_SHOWN
        poke_arrow.set_visible(poking and Lp > 0)
        poke_text.set_visible(poking)
        if poking:
            # The poke pushes the tip sideways, in the direction the angle then moves.
            length = 0.12 + 0.1 * Lp
            start = (tip[0] + poke_sign * length, tip[1])
            poke_arrow.set_positions(start, tip)
            poke_text.set_position((0.5 * (start[0] + tip[0]), tip[1] + 0.02))

    return _save(fig, writer, path, draw, frames, poke_start, dpi)


def _writer(path: Path, fps: int) -> animation.AbstractMovieWriter:
    """A GIF writer with one palette, or ffmpeg's for ``.mp4``."""
    suffix = path.suffix.lower()
    if suffix == ".gif":
        return _PaletteGifWriter(fps=fps)
    if suffix == ".mp4":
        if shutil.which("ffmpeg") is None:
            raise UserError(f"writing {path.name} needs ffmpeg, which is not installed; ask for a .gif instead")
        return animation.FFMpegWriter(fps=fps)
    raise UserError(f"animation file {path} must end in .gif or .mp4")


def _save(fig: Figure, writer: animation.AbstractMovieWriter, path: Path, draw: Any, frames: np.ndarray,
          marked: float | None, dpi: int) -> Path:
    """Draw every frame into ``path`` (atomically: a temporary file beside it, then renamed)."""
    if isinstance(writer, _PaletteGifWriter):
        # One palette for every frame, taken from a frame that shows everything (the poke too).
        marked_frames = np.flatnonzero(frames >= marked) if marked is not None else np.array([], int)
        draw(int(marked_frames[0]) if marked_frames.size else 0)
        writer.palette = _palette(fig)
    try:
        tmp = _temporary_beside(path)
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}; choose another folder") from None
    try:
        with writer.saving(fig, str(tmp), dpi):
            for i in range(frames.size):
                draw(i)
                writer.grab_frame()
        os.replace(tmp, path)
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}; check the folder's permissions") from None
    finally:
        tmp.unlink(missing_ok=True)
    return path


#: The seesaw as drawn (m): Quanser's track height above the pivot and the track's half length.
SEESAW_TRACK_HEIGHT = 0.125
SEESAW_HALF_LENGTH = 0.45


def animate_seesaw(
    columns: Mapping[str, Any],
    path: str | os.PathLike[str],
    *,
    tap_start: float | None = None,
    fps: int = 25,
    dpi: int = 80,
) -> Path:
    """Write an animation of a seesaw run: the track tilting about its pivot, the cart on it, the tap.

    Parameters
    ----------
    columns : mapping of name -> 1-D array
        ``t``, ``x`` and ``theta`` (the tilt, positive counter-clockwise: the +x end up).
    path : path
        Output file (``.gif``, or ``.mp4`` with ffmpeg); written atomically.
    tap_start : float, optional
        Time of the tap: an arrow on the +x end and "tap" for 0.2 s from then.

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, os, numpy as np
    >>> t = np.linspace(0.0, 0.4, 41)
    >>> cols = {"t": t, "x": 0.05 * t, "theta": 0.05 * np.sin(8 * t)}
    >>> animate_seesaw(cols, os.path.join(tempfile.mkdtemp(), "seesaw.gif"), tap_start=0.1, fps=10).name
    'seesaw.gif'
    """
    t, x, theta = _signals(columns, angle="theta")
    if not 1 <= fps <= 60:
        raise ValueError(f"fps={fps} must be between 1 and 60")
    path = Path(path)
    writer = _writer(path, fps)
    frames = np.arange(t[0], t[-1] + 1e-9, 1.0 / fps)
    xf, thf = np.interp(frames, t, x), np.interp(frames, t, theta)

    fig = Figure(figsize=(6.4, 3.2), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.02, 0.04, 0.96, 0.92))
    L, H = SEESAW_HALF_LENGTH, SEESAW_TRACK_HEIGHT
    ax.set_xlim(-0.55, 0.55)
    ax.set_ylim(-0.16, 0.30)
    ax.set_aspect("equal", adjustable="box")
    ax.set_axis_off()
    # Static scene: the floor and the pivot's stand.
    ax.plot([-0.55, 0.55], [-0.15, -0.15], color="0.5", lw=2)
    ax.fill([-0.05, 0.05, 0.0], [-0.15, -0.15, 0.0], color="0.6")
    (track,) = ax.plot([], [], color="0.35", lw=5, solid_capstyle="butt")
    (post,) = ax.plot([], [], color="0.35", lw=2)
    cart = ax.fill([], [], facecolor="C0", edgecolor="k", lw=1)[0]
    ax.plot([0], [0], "o", color="k", ms=5)
    clock = ax.text(0.01, 0.97, "", transform=ax.transAxes, va="top", family="monospace", fontsize=9)
    tap_arrow = FancyArrowPatch((0, 0), (0, 0), arrowstyle="-|>", mutation_scale=18, color="red", lw=2.5)
    ax.add_patch(tap_arrow)
    tap_text = ax.text(0, 0, "tap", color="red", fontsize=11, fontweight="bold", ha="center", va="bottom")

    def along(s: float, h: float, angle: float) -> tuple[float, float]:
        # A point s along the track and h above it, the seesaw tilted by angle about the pivot.
        return (s * math.cos(angle) - h * math.sin(angle), s * math.sin(angle) + h * math.cos(angle))

    def draw(i: int) -> None:
        xc, a = xf[i], thf[i]
        ends = [along(-L, H, a), along(L, H, a)]
        track.set_data([p[0] for p in ends], [p[1] for p in ends])
        top = along(0.0, H, a)
        post.set_data([0.0, top[0]], [0.0, top[1]])
        corners = [along(xc + dx, H + dy, a) for dx, dy in ((-CART_WIDTH / 2, 0), (CART_WIDTH / 2, 0), (CART_WIDTH / 2, CART_HEIGHT), (-CART_WIDTH / 2, CART_HEIGHT))]
        cart.set_xy(corners)
        clock.set_text(f"t = {frames[i]:6.3f} s   x = {100 * xc:+6.1f} cm   θ = {math.degrees(a):+6.2f}°")
        tapping = tap_start is not None and tap_start <= frames[i] < tap_start + POKE_SHOWN
        tap_arrow.set_visible(tapping)
        tap_text.set_visible(tapping)
        if tapping:
            end = along(L, H, a)
            tap_arrow.set_positions((end[0], end[1] - 0.12), end)  # a tap from below lifts the +x end
            tap_text.set_position((end[0], end[1] - 0.16))

    return _save(fig, writer, path, draw, frames, tap_start, dpi)


class _PaletteGifWriter(animation.PillowWriter):
    """PillowWriter that maps every frame onto one fixed palette as it is grabbed.

    Pillow's default per-frame palette search (quantizing each RGBA frame) takes about as long as
    drawing the frame; the rig's picture has few colours, so one shared palette is both faster
    and free of palette flicker between frames.
    """

    palette: Image.Image | None = None

    def setup(self, fig: Figure, outfile: Any, dpi: float | None = None) -> None:
        super().setup(fig, outfile, dpi)
        self._images: list[Image.Image] = []

    def grab_frame(self, **savefig_kwargs: Any) -> None:
        buffer = io.BytesIO()
        self.fig.savefig(buffer, **{**savefig_kwargs, "format": "rgba", "dpi": self.dpi})
        rgba = Image.frombuffer("RGBA", self.frame_size, buffer.getbuffer(), "raw", "RGBA", 0, 1)
        rgb = rgba.convert("RGB")
        if self.palette is None:
            self.palette = rgb.quantize(colors=64)
        self._images.append(rgb.quantize(palette=self.palette, dither=Image.Dither.NONE))

    def finish(self) -> None:
        self._images[0].save(
            self.outfile,
            save_all=True,
            append_images=self._images[1:],
            duration=round(1000 / self.fps),
            loop=0,
        )


def _palette(fig: Figure) -> Image.Image:
    canvas = fig.canvas
    canvas.draw()
    rgb = Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")
    return rgb.quantize(colors=64)


def _signals(columns: Mapping[str, Any], angle: str = "alpha") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if angle not in columns and f"{angle}_measured" in columns:
        angle = f"{angle}_measured"
    missing = [name for name in ("t", "x", angle) if name not in columns]
    if missing:
        raise ValueError(f"the animation needs columns t, x and {angle}; missing {', '.join(missing)}")
    t, x, alpha = (np.asarray(columns[name], dtype=float).reshape(-1) for name in ("t", "x", angle))
    if not t.size == x.size == alpha.size or t.size < 2:
        raise ValueError(f"the animation needs t, x and {angle} of the same length (at least 2 samples)")
    # A fallen or cut-off run may end in non-finite values: animate what is finite.
    ok = np.isfinite(t) & np.isfinite(x) & np.isfinite(alpha)
    if ok.sum() < 2:
        raise ValueError("the animation: fewer than 2 finite samples")
    return t[ok], x[ok], alpha[ok]


def _poke_direction(t: np.ndarray, alpha: np.ndarray, poke_start: float | None) -> float:
    """+1 if the poke pushes the tip toward +x, -1 toward -x (read from how the angle responds)."""
    if poke_start is None:
        return -1.0
    before = np.interp(poke_start, t, alpha)
    after = np.interp(poke_start + 0.03, t, alpha)
    # alpha rising means the tip moves toward -x; so the push came from the +x side toward -x.
    return 1.0 if after >= before else -1.0


def _temporary_beside(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = create_temporary(path.parent, path.name)
    os.close(fd)
    return tmp
