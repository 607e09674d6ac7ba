#!/usr/bin/env python3
"""Sweep throughput: runs per core-second against one-by-one simulation and the bare stepping loop (SPEC §11).

Bars: the sweep runs at least 20x the rate of ``pendulab.simulate`` called once per run, and at least
0.8x the rate of the bare stepping loop.

All measured in one run, on the same runs (the demo controller's gain over a grid, on plant samples
with drawn friction, damping and delay; 5 s each at 1 kHz, the lab's 220 rad/s^2 poke):

* **one by one**: ``pendulab.simulate(run_spec)`` called once per run, in this process, as a script
  would (load the three FMUs, run, measure, free), on ``--single`` of the runs;
* **bare loop**: one :class:`~pendulab.cosim.master.Master` holding the FMUs; each run is a reset, the
  run's start values and ``Master.run`` recording the nine signals, with the systems built
  beforehand: nothing but the FMUs' stepping and the master's work around it (no controller
  discretization, no parameters to build, no metrics, no results);
* **simulate, FMUs kept**: ``pendulab.simulate(run_spec, simulator=sim)`` in this process, the
  sweep's per-run work without its engine (FMU instances reset, not reloaded; metrics and verdict);
* **sweep**: :func:`pendulab.sweep.sweep` with ``--workers`` local worker processes on all the runs,
  from start to ``results.parquet``: worker start-up, FMU loading, metrics, Parquet parts and the
  final table all included.

Also measured: one worker's start-up (a worker process that starts, runs one run and ends, less one
run), which a sweep pays once per worker; the sweep's rate without it is printed beside the measured
one as what each further run costs (a derived figure: a larger sweep tends to it).

A rate is runs per core-second: runs divided by the CPU time of every process involved (the sweep's
own process and its workers, from ``getrusage``), so that it does not depend on how busy the shared
machine is; wall-clock rates are printed beside it. The one-by-one and bare-loop variants run in
turns (``--repeats``) and their medians are used.

Usage::

    python bench/sweep.py [--runs 1200] [--single 20] [--workers 2] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

ONE_BY_ONE_BAR = 20.0
BARE_BAR = 0.8

SPEC = """
[run]
stop_time = 5
poke = [220, 0.005, 1]

[controller]
demo = true

[grid]
"kernel.gain" = [{gains}]

[uncertainty]
samples = {samples}
seed = 1
F1 = {{ uniform = [1.0, 2.0] }}
Beq = {{ normal = [4.3, 0.4] }}
delay = {{ choice = [1, 2, 3] }}
"""


def cpu_children() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def worker_startup(spec, run) -> float:
    """Core-seconds of one sweep worker process that starts, runs ``run`` and ends (its imports, the FMUs loaded)."""
    from pendulab.sweep.sandbox import Sandbox

    c0 = cpu_children()
    sandbox = Sandbox()
    try:
        sandbox.run_batch(spec, [run])
    finally:
        sandbox.close()
    return cpu_children() - c0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1200, help="runs of the sweep (default 1200)")
    parser.add_argument("--single", type=int, default=20, help="runs simulated one by one and in the bare loop per repeat (default 20)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="sweep worker processes (default: one per core)")
    parser.add_argument("--repeats", type=int, default=3, help="turns of the one-by-one and bare-loop variants (default 3)")
    args = parser.parse_args()

    import pendulab
    from pendulab.cosim.master import Master
    from pendulab.cosim.pendulum import RECORDED
    from pendulab.simulation import Simulator, build_system
    from pendulab.sweep import sweep
    from pendulab.sweep.spec import parse_sweep_spec, runs_of

    gains = [20000, 30000, 40000, 60000]
    samples = max(1, args.runs // len(gains))
    spec = parse_sweep_spec(SPEC.format(gains=", ".join(map(str, gains)), samples=samples))
    runs = list(runs_of(spec))
    stop = spec.run["stop_time"]
    # The same runs for the two per-run variants: spread over the grid and the samples.
    chosen = runs[:: max(1, len(runs) // args.single)][: args.single]
    specs = [spec.run_spec(r[3]) for r in chosen]
    systems = [build_system(s, s.parameters()) for s in specs]

    def one_by_one() -> float:
        t0 = time.process_time()
        for run_spec in specs:
            pendulab.simulate(run_spec)
        return (time.process_time() - t0) / len(specs)

    def reused() -> float:
        with Simulator() as sim:
            pendulab.simulate(specs[0], simulator=sim)  # loading is not part of it
            t0 = time.process_time()
            for run_spec in specs:
                pendulab.simulate(run_spec, simulator=sim)
            return (time.process_time() - t0) / len(specs)

    def bare_loop() -> float:
        with Master(systems[0]) as master:
            master.run(stop, list(RECORDED))  # loading is not part of the loop
            t0 = time.process_time()
            for system in systems:
                master.reset(system)
                master.run(stop, list(RECORDED))
            return (time.process_time() - t0) / len(systems)

    one_by_one()  # warm: imports, the plan runner's library
    single, bare, reuse = [], [], []
    for _ in range(args.repeats):
        single.append(one_by_one())
        bare.append(bare_loop())
        reuse.append(reused())
    single_s, bare_s, reuse_s = statistics.median(single), statistics.median(bare), statistics.median(reuse)
    startup = statistics.median(worker_startup(spec, runs[0]) for _ in range(args.repeats)) - reuse_s

    with tempfile.TemporaryDirectory(prefix="pendulab-bench-sweep-") as tmp:
        c0, k0, w0 = time.process_time(), cpu_children(), time.perf_counter()
        result = sweep(spec, Path(tmp) / "out", workers=args.workers, plots=False)
        wall = time.perf_counter() - w0
        parent, children = time.process_time() - c0, cpu_children() - k0
        core = parent + children
    n = spec.n_runs
    sweep_rate = n / core
    single_rate, bare_rate = 1 / single_s, 1 / bare_s

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1 / 5 / 15 min) at the end")
    print(f"runs: {stop:g} s at 1 kHz (3 FMUs), demo controller gain x {samples} rigs; the sweep: {n} runs on {result.engine}")
    print(f"{'variant':<34}{'runs per core-s':>16}{'core-ms per run':>17}")
    print(f"{'pendulab.simulate one by one':<34}{single_rate:>16.1f}{1e3 * single_s:>17.2f}")
    print(f"{'bare stepping loop':<34}{bare_rate:>16.1f}{1e3 * bare_s:>17.2f}")
    print(f"{'simulate, FMUs kept (no engine)':<34}{1 / reuse_s:>16.1f}{1e3 * reuse_s:>17.2f}")
    print(f"{'sweep (' + str(args.workers) + ' workers, all included)':<34}{sweep_rate:>16.1f}{1e3 / sweep_rate:>17.2f}")
    print(f"sweep wall clock: {n / wall:.1f} runs/s ({wall:.1f} s for {n} runs; {core:.1f} core-s: "
          f"{parent:.2f} in the sweep's own process, {children:.2f} in its workers)")
    print(f"statuses: {', '.join(f'{v} {k}' for k, v in result.counts.items() if v)}")
    ratio_single, ratio_bare = sweep_rate / single_rate, sweep_rate / bare_rate
    ok_single, ok_bare = ratio_single >= ONE_BY_ONE_BAR, ratio_bare >= BARE_BAR
    print(f"sweep / one-by-one: {ratio_single:.2f}x (bar >= {ONE_BY_ONE_BAR:g}x) {'PASS' if ok_single else 'FAIL'}")
    print(f"sweep / bare loop:  {ratio_bare:.2f}x (bar >= {BARE_BAR:g}x) {'PASS' if ok_bare else 'FAIL'}")
    # The one-by-one bar's ceiling: a sweep cannot step faster than the bare loop, so it beats one-by-one
    # by at most (one-by-one time) / (bare-loop time).
    print(f"ceiling of sweep / one-by-one (one-by-one / bare loop): {single_s / bare_s:.2f}x")
    # Where the rest goes: a run's own work beyond stepping (controller realization looked up, the
    # plant's parameters, metrics and verdict, meta) and the engine's (batches, worker processes, Parquet).
    per_run = 1 / sweep_rate
    started = args.workers * startup / n
    print(f"per run beyond the bare loop: {1e3 * (reuse_s - bare_s):.2f} core-ms in simulate itself (metrics, verdict, "
          f"parameters), {1e3 * (per_run - reuse_s):.2f} core-ms in the sweep's engine: {1e3 * started:.2f} of them the "
          f"workers' start-up ({startup:.2f} core-s each: Python, numpy, fmpy, pendulab, the three FMUs loaded), "
          f"{1e3 * (per_run - reuse_s - started):.2f} batches, pipes and Parquet")
    # The start-up is paid once per worker: what each further run costs is the sweep's rate without it.
    marginal = 1 / (per_run - started)
    print(f"sweep without its workers' start-up (a larger sweep tends to it): {marginal:.1f} runs per core-s, "
          f"{marginal / bare_rate:.2f}x the bare loop, {marginal / single_rate:.2f}x one by one")
    return 0 if ok_single and ok_bare else 1


if __name__ == "__main__":
    raise SystemExit(main())
