"""Plots of a sweep (PNG): the share of balanced runs over the grid, and the metrics' distributions.

* ``stability_map.png``: the balanced share of each grid point (over its plant samples). One axis: a
  bar per value; two or more: a heat map over the first two axes, one panel per combination of the
  others (at most 12 panels; beyond that the share is averaged over the remaining axes).
* ``metrics.png``: a histogram of each metric over the balanced runs, and the count of each status.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import numpy as np

from pendulab.sweep.runner import STATUSES

#: Metrics shown in metrics.png.
SHOWN = ("natural_frequency_rad_s", "peak_time_s", "overshoot_percent", "settling_time_s", "limit_cycle_amplitude_rad", "cart_speed_change_m_s")
MAX_PANELS = 12


def balanced_share(spec: Any, table: Any) -> np.ndarray:
    """The balanced share of each grid point, shaped like the grid (axes in spec order)."""
    point = np.asarray(table.column("point").to_pylist())
    balanced = np.asarray([s == "balanced" for s in table.column("status").to_pylist()], dtype=float)
    share = np.bincount(point, weights=balanced, minlength=spec.n_points) / np.maximum(np.bincount(point, minlength=spec.n_points), 1)
    return share.reshape([len(a.values) for a in spec.axes] or [1])


def plot_sweep(spec: Any, table: Any, folder: Path) -> list[Path]:
    """Write the stability map (when the sweep has grid axes) and the metric distributions into ``folder``."""
    import matplotlib

    matplotlib.use("Agg")
    from pendulab.outputs import atomic_write

    folder.mkdir(parents=True, exist_ok=True)
    written = []
    figures = {"metrics.png": _metrics_figure(table)}
    if spec.axes:
        figures["stability_map.png"] = _map_figure(spec, balanced_share(spec, table))
    for name, figure in figures.items():
        written.append(atomic_write(folder / name, lambda f, fig=figure: fig.savefig(f, format="png", dpi=110)))
        import matplotlib.pyplot as plt

        plt.close(figure)
    return written


def _label(value: float) -> str:
    return f"{value:g}"


def _map_figure(spec: Any, share: np.ndarray) -> Any:
    import matplotlib.pyplot as plt

    axes = spec.axes
    title = f"balanced share over {spec.n_samples} plant sample{'s' if spec.n_samples > 1 else ''} per point"
    if len(axes) == 1:
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.bar([_label(v) for v in axes[0].values], share, color="tab:green")
        ax.set_xlabel(axes[0].name)
        ax.set_ylabel("balanced share")
        ax.set_ylim(0, 1)
        ax.set_title(title)
        fig.tight_layout()
        return fig
    rest = axes[2:]
    combos = list(itertools.product(*(range(len(a.values)) for a in rest)))
    if len(combos) > MAX_PANELS:
        share = share.reshape(share.shape[:2] + (-1,)).mean(axis=2)[..., None]
        combos, rest = [()], ()
        title += f" (mean over {', '.join(a.name for a in axes[2:])})"
    else:
        share = share.reshape(share.shape[:2] + (-1,))
    n = len(combos)
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig, grid = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.6 * rows), squeeze=False)
    image = None
    for k, combo in enumerate(combos):
        ax = grid[k // cols][k % cols]
        image = ax.imshow(share[:, :, k], origin="lower", vmin=0, vmax=1, cmap="RdYlGn", aspect="auto")
        ax.set_xticks(range(len(axes[1].values)), [_label(v) for v in axes[1].values])
        ax.set_yticks(range(len(axes[0].values)), [_label(v) for v in axes[0].values])
        ax.set_xlabel(axes[1].name)
        ax.set_ylabel(axes[0].name)
        if rest:
            ax.set_title(", ".join(f"{a.name}={_label(a.values[i])}" for a, i in zip(rest, combo)), fontsize=9)
        for (i, j), value in np.ndenumerate(share[:, :, k]):
            ax.text(j, i, f"{value:.0%}", ha="center", va="center", fontsize=7)
    for k in range(n, rows * cols):
        grid[k // cols][k % cols].axis("off")
    fig.colorbar(image, ax=grid.ravel().tolist(), label="balanced share")
    fig.suptitle(title)
    return fig


def _metrics_figure(table: Any) -> Any:
    import matplotlib.pyplot as plt

    statuses = table.column("status").to_pylist()
    balanced = np.asarray([s == "balanced" for s in statuses])
    fig, grid = plt.subplots(2, 4, figsize=(15, 6.5))
    cells = grid.ravel()
    counts = [statuses.count(s) for s in STATUSES]
    cells[0].bar([s.replace(" ", "\n") for s in STATUSES], counts, color=["tab:green", "tab:orange", "tab:red", "tab:olive", "tab:gray", "tab:purple"])
    cells[0].set_title(f"status of {len(statuses)} runs")
    for ax, name in zip(cells[1:], SHOWN):
        values = np.asarray([np.nan if v is None else v for v in table.column(name).to_pylist()], dtype=float)
        values = values[balanced & np.isfinite(values)]
        if values.size:
            ax.hist(values, bins=min(30, max(5, values.size // 4)), color="tab:blue")
        else:
            ax.text(0.5, 0.5, "no balanced run\nhas this metric", ha="center", va="center", transform=ax.transAxes)
            ax.set_xticks([])
            ax.set_yticks([])
        ax.set_title(name, fontsize=9)
    cells[-1].axis("off")
    fig.suptitle("metrics of the balanced runs")
    fig.tight_layout()
    return fig
