#!/usr/bin/env python3
"""The old lab's claim in numbers: how often does the nominal simulation's verdict hold on plausible rigs?

The old lab said its simulation "predicts stability about 95 % of the time". Here: the old lab's three
PIDs (Kp, Ki, Kd) = (600, 200, 5), (750, 6, 10), (1200, 20, 20) on the long pendulum with the lab's
220 rad/s^2, 5 ms poke, and the 27-point grid they span (every Kp x Ki x Kd of those values, the
issue's example), each run

* once on the nominal rig (the lab's friction table, no delay), and
* on ``--samples`` plausible rigs: the ``--robust`` defaults (friction ±30 %, Beq ±10 %, cart mass ±3 %,
  force gain ±5 %, poke ±25 %, delay 1-3 periods; :mod:`pendulab.sweep.robust`), the same rigs for
  every point.

It prints the probability of balancing on a plausible rig (each PID, and the grid), and the share of
grid points where the nominal verdict (balanced or not) agrees with the verdict of the majority of the
plausible rigs: our version of "predicts stability 95 % of the time". Also the share of points where
the nominal verdict is right on at least 95 % of the rigs. Both for "balanced" (the verdict's outcome)
and for "stayed up" (balanced, or cut at the track limit with the pendulum still up), which is what
the old lab's word "stable" meant.

The same measure follows on a grid whose verdict changes within it: the demo controller's kernel gain
from 10000 to 100000 (it balances at 40000).

Usage::

    python bench/old_lab_claim.py [--samples 50] [--workers 2] [--stop-time 5]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

OLD_LAB_PIDS = ((600.0, 200.0, 5.0), (750.0, 6.0, 10.0), (1200.0, 20.0, 20.0))
GRID = {"kp": [600, 750, 1200], "ki": [6, 20, 200], "kd": [5, 10, 20]}
#: The demo controller's kernel gain from a quarter to 2.5 times its 40000.
DEMO_GAINS = {"kernel.gain": [10000.0, 15000.0, 20000.0, 25000.0, 30000.0, 40000.0, 60000.0, 80000.0, 100000.0]}


def claim(title: str, run: dict, sections: dict, samples: int, workers: int, marked: set) -> None:
    """One grid, nominal and on ``samples`` plausible rigs: the table and the claim's numbers."""
    import numpy as np

    from pendulab.sweep import sweep
    from pendulab.sweep.robust import robust_uncertainty, wilson_interval
    from pendulab.sweep.spec import sweep_spec_from_dict

    nominal = sweep_spec_from_dict({"run": run, **sections}, source="nominal")
    uncertainty = robust_uncertainty(nominal.run_spec().parameters())
    rigs = sweep_spec_from_dict({"run": run, **sections,
                                 "uncertainty": {"samples": samples, "seed": 1, **uncertainty}}, source="rigs")
    with tempfile.TemporaryDirectory(prefix="pendulab-old-lab-") as tmp:
        n = sweep(nominal, Path(tmp) / "nominal", workers=workers, plots=False)
        r = sweep(rigs, Path(tmp) / "rigs", workers=workers, plots=False)
    points = nominal.points()
    names = [a.name for a in nominal.axes]
    nominal_status = n.table.column("status").to_pylist()
    statuses = np.asarray(r.table.column("status").to_pylist()).reshape(len(points), samples)
    print(f"\n== {title}: {len(points)} points x {samples} plausible rigs ({r.elapsed:.0f} s on {r.engine}); "
          f"{run['stop_time']:g} s runs, poke {run['poke'][0]:g} rad/s^2 for {1e3 * run['poke'][1]:g} ms")
    print(f"statuses on the rigs: {', '.join(f'{v} {k}' for k, v in r.counts.items() if v)}; "
          f"nominal: {', '.join(f'{v} {k}' for k, v in n.counts.items() if v)}")
    print("".join(f"{a:>10}" for a in names) + f"  {'nominal':<9}{'balanced on rigs':>17}  95 % CI      outcomes on the rigs")
    for g, point in enumerate(points):
        k = int((statuses[g] == "balanced").sum())
        low, high = wilson_interval(k, samples)
        outcomes = {str(s): int((statuses[g] == s).sum()) for s in sorted(set(statuses[g]))}
        mark = "  <- old lab" if tuple(point.values()) in marked else ""
        print("".join(f"{point[a]:>10g}" for a in names) + f"  {nominal_status[g]:<9}{100 * k / samples:>16.0f}%  "
              f"{100 * low:3.0f}-{100 * high:3.0f} %  {outcomes}{mark}")
    for label, good in (("balanced", lambda s: s == "balanced"), ("stayed up (balanced, or cut at the track before a fall)",
                                                                   lambda s: s in ("balanced", "cut"))):
        ok = np.vectorize(good)(statuses)
        nominal_ok = np.asarray([good(s) for s in nominal_status])
        share = ok.mean(axis=1)
        agree = nominal_ok == (share > 0.5)
        right95 = np.where(nominal_ok, share, 1 - share) >= 0.95
        k = int(ok.sum())
        low, high = wilson_interval(k, ok.size)
        print(f"[{label}] P on a plausible rig: {100 * k / ok.size:.1f} % (95 % CI {100 * low:.1f}-{100 * high:.1f} %)", end="")
        if marked:
            idx = [g for g, p in enumerate(points) if tuple(p.values()) in marked]
            k_old = int(ok[idx].sum())
            lo, hi = wilson_interval(k_old, len(idx) * samples)
            print(f"; the old lab's PIDs: {100 * k_old / (len(idx) * samples):.1f} % (95 % CI {100 * lo:.1f}-{100 * hi:.1f} %)", end="")
        print(f"; the nominal verdict agrees with the rigs' majority at {int(agree.sum())}/{len(points)} points "
              f"({100 * agree.mean():.0f} %), holds on >= 95 % of the rigs at {int(right95.sum())} ({100 * right95.mean():.0f} %)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=50, help="plausible rigs per grid point (default 50)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes (default: one per core)")
    parser.add_argument("--stop-time", type=float, default=5.0, help="seconds per run (default 5, the old lab's)")
    args = parser.parse_args()
    run = {"pendulum": "long", "stop_time": args.stop_time, "poke": [220.0, 0.005, 1.0]}
    claim("the old lab's three PIDs and their grid", run, {"controller": {"pid": {k: list(map(float, v)) for k, v in GRID.items()}}},
          args.samples, args.workers, set(OLD_LAB_PIDS))
    # The same measure where the verdict is not the same everywhere: the demo controller's gain across
    # the edge of its stable range under the lab's hard poke.
    claim("the demo controller's gain across its edge", run, {"controller": {"demo": True}, "grid": DEMO_GAINS}, args.samples, args.workers, set())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
