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
the nominal verdict is right on at least 95 % of the rigs.

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


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=50, help="plausible rigs per grid point (default 50)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes (default: one per core)")
    parser.add_argument("--stop-time", type=float, default=5.0, help="seconds per run (default 5, the old lab's)")
    args = parser.parse_args()

    import numpy as np

    from pendulab.sweep import sweep
    from pendulab.sweep.robust import robust_uncertainty, wilson_interval
    from pendulab.sweep.spec import sweep_spec_from_dict

    run = {"pendulum": "long", "stop_time": args.stop_time, "poke": [220.0, 0.005, 1.0]}
    controller = {"pid": {k: list(map(float, v)) for k, v in GRID.items()}}
    nominal = sweep_spec_from_dict({"run": run, "controller": controller}, source="nominal")
    uncertainty = robust_uncertainty(nominal.run_spec().parameters())
    rigs = sweep_spec_from_dict({"run": run, "controller": controller,
                                 "uncertainty": {"samples": args.samples, "seed": 1, **uncertainty}}, source="rigs")
    with tempfile.TemporaryDirectory(prefix="pendulab-old-lab-") as tmp:
        n = sweep(nominal, Path(tmp) / "nominal", workers=args.workers, plots=False)
        r = sweep(rigs, Path(tmp) / "rigs", workers=args.workers, plots=False)
    points = nominal.points()
    nominal_status = n.table.column("status").to_pylist()
    statuses = np.asarray(r.table.column("status").to_pylist()).reshape(len(points), args.samples)
    balanced = statuses == "balanced"
    print(f"{len(points)} PID points x {args.samples} plausible rigs ({r.elapsed:.0f} s on {r.engine}); "
          f"{args.stop_time:g} s runs, poke 220 rad/s^2 for 5 ms")
    print(f"statuses on the rigs: {', '.join(f'{v} {k}' for k, v in r.counts.items() if v)}; "
          f"nominal: {', '.join(f'{v} {k}' for k, v in n.counts.items() if v)}")
    print(f"{'Kp':>6}{'Ki':>6}{'Kd':>5}  {'nominal':<9}{'balanced on rigs':>18}  95 % CI     other outcomes")
    for g, point in enumerate(points):
        k = int(balanced[g].sum())
        low, high = wilson_interval(k, args.samples)
        old = "  <- old lab" if tuple(point[a] for a in ("kp", "ki", "kd")) in OLD_LAB_PIDS else ""
        others = {s: int((statuses[g] == s).sum()) for s in ("cut", "fell", "error", "timeout") if (statuses[g] == s).any()}
        print(f"{point['kp']:>6g}{point['ki']:>6g}{point['kd']:>5g}  {nominal_status[g]:<9}{100 * k / args.samples:>17.0f}%  "
              f"{100 * low:3.0f}-{100 * high:3.0f} %  {others}{old}")
    share = balanced.mean(axis=1)
    nominal_balanced = np.asarray([s == "balanced" for s in nominal_status])
    agree = nominal_balanced == (share > 0.5)
    right95 = np.where(nominal_balanced, share, 1 - share) >= 0.95
    k_all = int(balanced.sum())
    low, high = wilson_interval(k_all, balanced.size)
    old_idx = [g for g, p in enumerate(points) if tuple(p[a] for a in ("kp", "ki", "kd")) in OLD_LAB_PIDS]
    k_old = int(balanced[old_idx].sum())
    lo_old, hi_old = wilson_interval(k_old, len(old_idx) * args.samples)
    print(f"P(balance) on a plausible rig, the old lab's three PIDs: {100 * k_old / (len(old_idx) * args.samples):.0f} % "
          f"(95 % CI {100 * lo_old:.0f}-{100 * hi_old:.0f} %)")
    print(f"P(balance) on a plausible rig, the 27-point grid: {100 * k_all / balanced.size:.0f} % (95 % CI {100 * low:.0f}-{100 * high:.0f} %)")
    print(f"nominal verdict agrees with the majority of the rigs at {int(agree.sum())} of {len(points)} points "
          f"({100 * agree.mean():.0f} %); it holds on >= 95 % of the rigs at {int(right95.sum())} ({100 * right95.mean():.0f} %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
