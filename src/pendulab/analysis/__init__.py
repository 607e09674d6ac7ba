"""What comes out of a run: metrics, result files, plots and the rig animation (SPEC §7).

- :mod:`pendulab.analysis.metrics` -- :func:`compute_metrics` (``metrics.json``'s numbers);
- :mod:`pendulab.analysis.results` -- :data:`COLUMNS`, :func:`write_results` (``run.mat``,
  ``run.csv``, ``metrics.json``), :func:`read_run`, :class:`RunLog` (streamed CSV log);
- :mod:`pendulab.analysis.plots` -- :func:`plot_run`, :func:`plot_root_locus` (PNG, off-screen);
- :mod:`pendulab.analysis.animation` -- :func:`animate_run` (GIF of the rig).

The plotting modules import matplotlib, so they are not imported here; import them directly.
"""

from pendulab.analysis.metrics import METRIC_KEYS, compute_metrics
from pendulab.analysis.results import COLUMNS, RunLog, read_run, write_results

__all__ = ["COLUMNS", "METRIC_KEYS", "RunLog", "compute_metrics", "read_run", "write_results"]
