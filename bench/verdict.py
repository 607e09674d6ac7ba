#!/usr/bin/env python3
"""How well a 5 s run's verdict predicts a 20 s run: the old lab's "predicts stability about 95 % of the time".

Draws seeded controllers in four families, in turn: around the demo (``40000 (s+5)(s+17)/((s-7)(s+80)^2)``)
with the gain spread over a decade and every zero and pole over half a decade ("demo"), or every one
over a decade ("demo-wide"); around the README's kernel example (``45000 (s+6)(s+16)/((s-6.4)(s+80)^2)``,
gain a decade, roots half a decade: "kernel"); and around the old lab's three PIDs (``600,200,5``,
``750,6,10``, ``1200,20,20``, each gain over a decade: "pid"). A spread of ``d`` decades multiplies
each number by its own factor ``10**U(-d/2, d/2)``. Each runs on either pendulum (the PIDs on the long
one, as in the old lab), with the default poke (50 rad/s²) or the lab's (220 rad/s²; always for the
PIDs), and a transport delay of 0, 1 or 2 periods (the rig's). Each is simulated
for 5 s and for 20 s through :func:`pendulab.simulate`, whose result carries the verdict of
:mod:`pendulab.analysis.verdict`. It prints

* **trust**: among the 5 s runs judged "balanced without warnings", the share whose 20 s run is not
  cut and does not fall;
* **warned**: among the 20 s runs that are cut or fall, the share whose 5 s run was flagged (a
  warning, a 5 s run that already failed, or the linear check's "no gain can balance");

both aimed at >= 95 %. The counts behind them, the outcomes of each family, and the cases that
miss are listed. ``tests/test_verdict_corpus.py`` runs a small part of it.

Usage::

    python bench/verdict.py [--n 200] [--seed 24]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np

OLD_LAB_PIDS = ((600.0, 200.0, 5.0), (750.0, 6.0, 10.0), (1200.0, 20.0, 20.0))
DEMO = (((-5.0,), (7.0,), 40000.0), ((-17.0,), (-80.0,), 1.0), ((), (-80.0,), 1.0))
#: The README's kernel example (a lead kernel with a right-half-plane pole and two filters).
README_KERNEL = (((-6.0,), (6.4,), 45000.0), ((-16.0,), (-80.0,), 1.0), ((), (-80.0,), 1.0))
#: Families: name -> (base factors or None for the PIDs, spread of the gain, spread of zeros and poles), in decades.
FAMILIES = {
    "demo": (DEMO, 1.0, 0.5),
    "demo-wide": (DEMO, 1.0, 1.0),
    "kernel": (README_KERNEL, 1.0, 0.5),
    "pid": (None, 1.0, 1.0),
}


@dataclass(frozen=True)
class Case:
    """One drawn controller and the run's settings."""

    family: str
    controller: Any
    pendulum: str
    poke: float
    delay: int

    def label(self) -> str:
        return f"{self.family} {self.controller} ({self.pendulum}, poke {self.poke:g}, delay {self.delay})"


def draw(n: int, seed: int = 24) -> list[Case]:
    """``n`` seeded cases, the families of :data:`FAMILIES` in turn."""
    from pendulab.control.controller import Controller, Factor

    rng = np.random.default_rng(seed)

    def spread(decades: float) -> float:
        return float(10 ** rng.uniform(-decades / 2, decades / 2))

    names = list(FAMILIES)
    cases = []
    for i in range(n):
        family = names[i % len(names)]
        base, gain_spread, root_spread = FAMILIES[family]
        pendulum = "long" if rng.random() < 0.6 else "short"
        poke = 50.0 if rng.random() < 0.5 else 220.0
        delay = int(rng.integers(0, 3))
        if base is None:
            kp, ki, kd = OLD_LAB_PIDS[int(rng.integers(0, 3))]
            pid = Controller.pid(kp * spread(gain_spread), ki * spread(gain_spread), kd * spread(gain_spread))
            cases.append(Case(family, pid, "long", 220.0, delay))
            continue
        factors = [
            Factor([z * spread(root_spread) for z in zeros], [p * spread(root_spread) for p in poles],
                   gain * (spread(gain_spread) if k == 0 else 1.0), label="kernel" if k == 0 else f"compensator {k}")
            for k, (zeros, poles, gain) in enumerate(base)
        ]
        cases.append(Case(family, Controller(factors), pendulum, poke, delay))
    return cases


def evaluate(case: Case, stop_times: tuple[float, ...] = (5.0, 20.0)) -> dict[str, Any]:
    """The case's linear prediction and its verdict at each stop time."""
    from pendulab.control.loop import linear_prediction
    from pendulab.model.parameters import PlantParameters
    from pendulab.simulation import simulate
    from pendulab.spec import RunSpec, Timing

    params = PlantParameters.preset(case.pendulum).with_values(poke_magnitude=case.poke)
    prediction = linear_prediction(case.controller, params, delay=case.delay)
    verdicts = {}
    for stop in stop_times:
        result = simulate(RunSpec.for_parameters(case.controller, params, timing=Timing(stop_time=stop, delay=case.delay)))
        verdicts[stop] = result.verdict
    return {"prediction": prediction, "verdicts": verdicts}


def flagged(record: dict[str, Any], short: float = 5.0) -> bool:
    """The short run told the student something was wrong: not clean, or the linear check's 'never'."""
    return (not record["verdicts"][short].clean) or record["prediction"].never is not None


def summarize(records: list[tuple[Case, dict[str, Any]]], short: float = 5.0, long: float = 20.0) -> dict[str, Any]:
    """The two shares and their counts."""
    clean = [(c, r) for c, r in records if r["verdicts"][short].clean and r["prediction"].never is None]
    clean_survive = [(c, r) for c, r in clean if r["verdicts"][long].outcome == "balanced"]
    failures = [(c, r) for c, r in records if r["verdicts"][long].outcome != "balanced"]
    warned = [(c, r) for c, r in failures if flagged(r, short)]
    return {
        "n": len(records),
        "clean": len(clean),
        "clean_survive": len(clean_survive),
        "trust": len(clean_survive) / len(clean) if clean else None,
        "failures": len(failures),
        "warned": len(warned),
        "warned_share": len(warned) / len(failures) if failures else None,
        "flagged_balanced": len([1 for c, r in records if flagged(r, short) and r["verdicts"][short].outcome == "balanced"]),
        "flagged_balanced_survive": len([1 for c, r in records if flagged(r, short) and r["verdicts"][short].outcome == "balanced"
                                         and r["verdicts"][long].outcome == "balanced"]),
        "missed_failures": [c for c, r in failures if not flagged(r, short)],
        "false_clean": [c for c, r in clean if r["verdicts"][long].outcome != "balanced"],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=200, help="controllers drawn (default 200)")
    parser.add_argument("--seed", type=int, default=24, help="random seed (default 24)")
    args = parser.parse_args(argv)
    started = time.perf_counter()
    cases = draw(args.n, args.seed)
    records = []
    for i, case in enumerate(cases, 1):
        records.append((case, evaluate(case)))
        if sys.stderr.isatty():
            print(f"\r  {i}/{len(cases)}", end="", file=sys.stderr, flush=True)
    if sys.stderr.isatty():
        print(file=sys.stderr)
    s = summarize(records)
    print(f"{s['n']} controllers (seed {args.seed}), 5 s and 20 s runs, {time.perf_counter() - started:.0f} s")
    for family in FAMILIES:
        rows = [(c, r) for c, r in records if c.family == family]
        short = Counter(("clean" if r["verdicts"][5.0].clean else r["verdicts"][5.0].outcome + ("+warn" if r["verdicts"][5.0].warnings else "")) for _, r in rows)
        long = Counter(r["verdicts"][20.0].outcome for _, r in rows)
        print(f"  {family:9s} {len(rows):3d}: 5 s {dict(short)}; 20 s {dict(long)}")
    warnings = Counter(w.kind for _, r in records for w in r["verdicts"][5.0].warnings)
    print(f"  5 s warnings raised: {dict(warnings)}")
    trust = "n/a" if s["trust"] is None else f"{100 * s['trust']:.1f} %"
    warned = "n/a" if s["warned_share"] is None else f"{100 * s['warned_share']:.1f} %"
    print(f"trust : {s['clean_survive']}/{s['clean']} 5 s runs balanced without warnings survive 20 s = {trust} (aim >= 95 %)")
    print(f"warned: {s['warned']}/{s['failures']} 20 s failures were flagged by the 5 s run = {warned} (aim >= 95 %)")
    print(f"(false alarms: {s['flagged_balanced_survive']} of the {s['flagged_balanced']} 5 s runs balanced with a warning survived 20 s)")
    balanced = [r for _, r in records if r["verdicts"][5.0].outcome == "balanced"]
    late = [r for r in balanced if r["verdicts"][20.0].outcome != "balanced"]
    print(f"late failures (balanced at 5 s, cut or fell by 20 s): {len(late)}, flagged at 5 s: {sum(flagged(r) for r in late)}")
    for kind in ("saturation", "chattering", "drift", "small margin"):
        raised = [r for r in balanced if any(w.kind == kind for w in r["verdicts"][5.0].warnings)]
        failed = sum(1 for r in raised if r["verdicts"][20.0].outcome != "balanced")
        print(f"  {kind:12s}: on {len(raised):3d} balanced 5 s runs; {failed} of them cut or fell within 20 s")
    for case in s["false_clean"]:
        print(f"  clean at 5 s but failed at 20 s: {case.label()}")
    for case in s["missed_failures"]:
        print(f"  failure not flagged at 5 s: {case.label()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
