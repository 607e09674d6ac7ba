"""Robustness for students: one controller on N plausible rigs, and how sure its "balances" is.

``pendulab simulate ... --robust N`` runs the student's controller on N rigs drawn from the
calibration's spread (when its file records one) or from the documented defaults below, and says in
one line how many it balances on, with a 95 % Wilson score interval (scipy), e.g.::

    balances on 97 % (95 % CI 93-99 %) of 200 plausible rigs

The worst case's run is simulated again and saved as a normal run (``run.mat``, ``run.csv``,
``metrics.json``) so that the student can look at it.

Default uncertainty of a plausible rig (:data:`DEFAULT_UNCERTAINTY`), relative to the run's values:

==============  ===================  ====================================================
parameter       draw                 why
==============  ===================  ====================================================
F1, F2          uniform ±30 %        ramp tests on one rig spread by this much (SPEC §8)
v1, v2, B       uniform ±30 %        the same ramp tests
Beq             normal, sd 10 %      the cart's damping changes with the belt and grease
M_cart          normal, sd 3 %       cables and the encoder's connector
force_gain      normal, sd 5 %       amplifier and motor constants (the fit's force gain)
poke_magnitude  uniform ±25 %        the poke is given by hand
delay           choice 1, 2, 3       the rig's transport delay (SPEC §9: 1, 2-3 over USB)
==============  ===================  ====================================================
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

#: name -> (kind, relative size) of the default draws, about the run's own value (see the module docstring).
DEFAULT_UNCERTAINTY: dict[str, tuple[str, float]] = {
    "F1": ("uniform", 0.30),
    "v1": ("uniform", 0.30),
    "F2": ("uniform", 0.30),
    "v2": ("uniform", 0.30),
    "B": ("uniform", 0.30),
    "Beq": ("normal", 0.10),
    "M_cart": ("normal", 0.03),
    "force_gain": ("normal", 0.05),
    "poke_magnitude": ("uniform", 0.25),
}
DEFAULT_DELAYS = (1, 2, 3)
CONFIDENCE = 0.95
#: Order of badness for the worst case: a fall before a cut before a balanced run.
_RANK = {"fell": 0, "cut": 1, "balanced": 2}


@dataclass(frozen=True)
class RobustResult:
    """How one controller fares on ``n`` plausible rigs."""

    n: int
    balanced: int
    low: float
    high: float
    counts: dict[str, int]
    worst: dict[str, Any] | None
    sweep: Any
    sweep_spec: Any

    @property
    def share(self) -> float:
        return self.balanced / self.n

    def line(self) -> str:
        """The one-line answer, e.g. ``balances on 97 % (95 % CI 93–99 %) of 200 plausible rigs``."""
        text = (f"balances on {100 * self.share:.0f} % ({100 * CONFIDENCE:.0f} % CI {100 * self.low:.0f}–{100 * self.high:.0f} %) "
                f"of {self.n} plausible rigs")
        failed = self.counts.get("error", 0) + self.counts.get("timeout", 0)
        return text + (f" ({failed} could not be simulated)" if failed else "")


def wilson_interval(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """The Wilson score interval of ``k`` successes in ``n`` trials (scipy's ``binomtest``).

    Examples
    --------
    >>> [round(v, 3) for v in wilson_interval(194, 200)]
    [0.936, 0.986]
    """
    from scipy.stats import binomtest

    ci = binomtest(k, n).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)


def robust_uncertainty(params: Any, calibration_spread: Mapping[str, float] | None = None) -> dict[str, Any]:
    """The ``[uncertainty]`` tables of plausible rigs about ``params`` (the calibration's spread first)."""
    table: dict[str, Any] = {}
    spread = dict(calibration_spread or {})
    for name, (kind, size) in DEFAULT_UNCERTAINTY.items():
        value = float(getattr(params, name))
        if name in spread:
            table[name] = {"normal": [value, spread[name]]}
        elif value == 0:
            continue  # a switched-off term (no friction, no poke) stays off
        elif kind == "uniform":
            table[name] = {"uniform": sorted([value * (1 - size), value * (1 + size)])}
        else:
            table[name] = {"normal": [value, abs(value) * size]}
    table["delay"] = {"choice": list(DEFAULT_DELAYS)}
    return table


def worst_run(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The worst run among those with a verdict: a fall, else the earliest cut, else the slowest to settle."""
    judged = [r for r in rows if r["status"] in _RANK]
    if not judged:
        return None

    def badness(r: dict[str, Any]) -> tuple:
        cut = r.get("safety_cut_time_s")
        settle = r.get("settling_time_s")
        return (_RANK[r["status"]], cut if cut is not None else math.inf, -(settle if settle is not None else math.inf),
                -(r.get("limit_cycle_amplitude_rad") or 0.0), r["run_id"])

    return min(judged, key=badness)


def robustness(
    spec: Any,
    n: int,
    out: str | os.PathLike[str],
    *,
    seed: int = 1,
    workers: int | None = None,
    scheduler: str | None = None,
    overwrite: bool = False,
    progress: Any = None,
) -> RobustResult:
    """Run the controller of ``spec`` (a :class:`~pendulab.spec.RunSpec`) on ``n`` plausible rigs.

    The rigs are drawn about the spec's plant (its preset and calibration) from the calibration's
    spread where its file records one, else from :data:`DEFAULT_UNCERTAINTY`; the delay from
    :data:`DEFAULT_DELAYS`. The sweep goes into the folder ``out``.

    Examples
    --------
    >>> import pendulab
    >>> from pendulab.control import demo_controller
    >>> # skipped: 200 runs of 5 s (tests/test_sweep.py runs a small one)
    >>> answer = robustness(pendulab.RunSpec(demo_controller()), 200, "runs/robust")   # doctest: +SKIP
    >>> answer.line()                                                                   # doctest: +SKIP
    'balances on 100 % (95 % CI 98–100 %) of 200 plausible rigs'
    """
    from pendulab.errors import UserError
    from pendulab.sweep import sweep
    from pendulab.sweep.spec import sweep_spec_from_dict

    if n < 1:
        raise UserError(f"--robust {n}: give the number of plausible rigs, at least 1 (e.g. --robust 200)")
    if spec.controller.transfer_function is None or spec.plant.overrides:
        raise UserError("--robust takes a run with a transfer-function controller and the plant of a preset and calibration")
    run = {
        "pendulum": spec.plant.pendulum, "cart": spec.plant.cart, "calibration": spec.plant.calibration,
        "stop_time": spec.timing.stop_time, "step": spec.timing.step, "method": spec.timing.method, "delay": spec.timing.delay,
        "poke": [spec.poke.magnitude, spec.poke.duration, spec.poke.start], "quantization": spec.quantization.enabled,
        "supervisor": {f.name: getattr(spec.supervisor, f.name) for f in dataclasses.fields(spec.supervisor)
                       if getattr(spec.supervisor, f.name) is not None},
        "start": spec.plant.start,
    }
    run = {k: v for k, v in run.items() if v is not None}
    controller = spec.controller.transfer_function.to_dict()
    base = sweep_spec_from_dict({"run": run, "controller": controller}, source="--robust")
    uncertainty = robust_uncertainty(base.run_spec().parameters(), base.run.get("_calibration_spread"))
    rigs = sweep_spec_from_dict({"run": run, "controller": controller, "uncertainty": {"samples": n, "seed": seed, **uncertainty}},
                                source="--robust")
    result = sweep(rigs, Path(out), workers=workers, scheduler=scheduler, overwrite=overwrite, plots=True, progress=progress)
    rows = result.table.to_pylist()
    k = result.counts["balanced"]
    low, high = wilson_interval(k, n)
    return RobustResult(n, k, low, high, result.counts, worst_run(rows), result, rigs)
