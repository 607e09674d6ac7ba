#!/usr/bin/env python3
"""The host's own pauses in ``calibrate --port``'s loop, with and without lab's measure against the garbage collector.

A rig's watchdog trips when an answer comes more than 20 ms late. On a shared host most of that lateness
is the operating system's (see bench/watchdog_trips.py); this bench measures the part that is the host
program's own: the time from a sample's arrival to its answer, for every sample of a ramp test run
in process against a link that answers at once (no pty, no emulator: nothing but calibrate's code), with the
cyclic garbage collector on (as calibrate ran before) and off and frozen (``no_garbage_collection``, as lab
and now calibrate run). The libraries calibrate loads (numpy, pyserial, fmpy, CasADi through the extraction
module) are imported first, as in the command, so a full collection has as much to walk as there.

Usage::

    python bench/calibrate_pauses.py [--seconds 40] [--repeats 3]
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


class InstantLink:
    """A rig link whose samples come at once: the cart creeps in the commanded direction above 1 V."""

    def __init__(self, seconds: float) -> None:
        from pendulab.hil import protocol as P

        self.P = P
        self.identity = P.Identity(0, boot_id=1)
        self.name, self.delay = "instant", 1
        self.k, self.stop_at = 0, int(seconds * 1000)
        self.x, self.v = 0, 0.0
        self.waits: list[float] = []
        self._got = 0.0

    def next_sample(self, timeout: float):
        if self.k >= self.stop_at:
            raise KeyboardInterrupt  # the end of the measured stretch: the ramp test keeps what it has
        self.k += 1
        if abs(self.v) > 1.0:
            self.x += int(np.sign(self.v) * 3)
        self._got = time.perf_counter()
        return self.P.Sample(self.k & 0xFFFF, tick=self.k, cart=self.x & 0xFFFF, voltage_mv=int(self.v * 1000)), self._got

    def command(self, answers: int, voltage: float, **kwargs) -> None:
        self.waits.append(time.perf_counter() - self._got)
        self.v = voltage

    def stream(self, on: bool) -> None:
        pass

    def motor_off(self, answers: int = 0) -> None:
        pass

    def silence_cause(self, silent_ms: float) -> Exception:
        raise AssertionError("never silent")


def one(seconds: float, quiet: bool) -> np.ndarray:
    from pendulab.analysis.results import RunLog
    from pendulab.calibration.ramp import run_ramp_test
    from pendulab.hil.realtime import no_garbage_collection
    from pendulab.hil.rig import LOG_COLUMNS, HilRig

    link = InstantLink(seconds)
    with tempfile.TemporaryDirectory() as tmp:
        log = RunLog(Path(tmp) / "log.csv", LOG_COLUMNS, flush_every=10)
        with HilRig(link, log=log) as rig, (no_garbage_collection() if quiet else contextlib.nullcontext()):  # type: ignore[arg-type]
            run_ramp_test(rig, iterations=5)
        log.close()
    return np.asarray(link.waits) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=40.0, help="samples per run, in rig seconds (default 40)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    import casadi  # noqa: F401 - what calibrate has loaded when it runs (the extraction, the FMU tools)
    import fmpy  # noqa: F401
    import serial  # noqa: F401

    import pendulab.calibration.extract  # noqa: F401

    print(f"tracked objects at the start: {len(gc.get_objects())}")
    results: dict[str, list[np.ndarray]] = {"gc on (before)": [], "gc off, frozen (after)": []}
    for _ in range(args.repeats):
        for name in results:
            results[name].append(one(args.seconds, quiet=name.startswith("gc off")))
    print(f"\nanswer time of each sample (ms), {args.repeats} runs of {args.seconds:g} s of samples each:")
    print("| loop | p50 | p99.9 | max | answers over 5 ms | over 20 ms |")
    print("|---|---|---|---|---|---|")
    for name, runs in results.items():
        w = np.concatenate(runs)
        print(f"| {name} | {np.percentile(w, 50):.3f} | {np.percentile(w, 99.9):.3f} | {w.max():.1f} | "
              f"{int((w > 5).sum())} of {w.size} | {int((w > 20).sum())} |")
    worst = {name: statistics.median(float(r.max()) for r in runs) for name, runs in results.items()}
    before, after = worst.values()
    print(f"\nmedian of the runs' longest answer: before {before:.1f} ms, after {after:.1f} ms (ratio {before / max(after, 1e-9):.1f})")


if __name__ == "__main__":
    main()
