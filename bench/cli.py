#!/usr/bin/env python3
"""``pendulab simulate`` with flags, from the start of the command to ``run.mat`` (SPEC §11).

Bar: < 3 s.

The command runs as a user runs it (the console script, a fresh process each time, a new output
folder), ``--repeats`` times (default 5) in turns with baselines measured in the same run, so that
the ratios hold on any machine:

* ``python -c pass``: the interpreter's own start;
* ``python -c "import pendulab"``: the package's top level;
* ``python -c "import control"``: python-control, which the controller code imports (with scipy.signal
  and matplotlib), the largest part of the start-up.

Each run is timed by wall clock and by the child's CPU time (user + system, from ``getrusage``); on a
loaded machine the wall clock also counts waiting for a core. The default simulation is 5 s of the
loop at 1 kHz with the poke at 1 s.

Usage::

    python bench/cli.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BAR_S = 3.0
FLAGS = ["--zeros=-5", "--poles=7", "--gain", "40000", "--compensator=-17;-80", "--compensator=none;-80"]


def pendulab_script() -> list[str]:
    script = Path(sys.executable).with_name("pendulab")
    if script.exists():
        return [str(script)]
    found = shutil.which("pendulab")
    return [found] if found else [sys.executable, "-m", "pendulab"]


def timed(command: list[str], check_file: Path | None = None) -> tuple[float, float]:
    """Wall and CPU seconds of one run of ``command`` (its output discarded)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    result = subprocess.run(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({result.returncode}): {result.stderr.strip()}")
    if check_file is not None and not check_file.is_file():
        raise SystemExit(f"{' '.join(command)} wrote no {check_file}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs per command (default 5)")
    args = parser.parse_args()
    script = pendulab_script()

    with tempfile.TemporaryDirectory(prefix="pendulab-bench-cli-") as tmp:
        counter = iter(range(10**6))

        def simulate(*extra: str) -> tuple[float, float]:
            out = Path(tmp) / f"run{next(counter)}"
            return timed([*script, "simulate", *extra, "--out", str(out)], out / "run.mat")

        commands = {
            "pendulab simulate with flags (kernel + 2 compensators)": lambda: simulate(*FLAGS),
            "pendulab simulate --demo": lambda: simulate("--demo"),
            'python -c "import control"': lambda: timed([sys.executable, "-c", "import control"]),
            'python -c "import pendulab"': lambda: timed([sys.executable, "-c", "import pendulab"]),
            "python -c pass": lambda: timed([sys.executable, "-c", "pass"]),
        }
        simulate("--demo")  # warm-up: FMUs built if missing, helper library compiled, file caches filled
        walls: dict[str, list[float]] = {name: [] for name in commands}
        cpus: dict[str, list[float]] = {name: [] for name in commands}
        for _ in range(args.repeats):
            for name, run in commands.items():
                wall, cpu = run()
                walls[name].append(wall)
                cpus[name].append(cpu)

    print(f"{' '.join(script)} simulate: 5 s of the loop at 1 kHz, run.mat + run.csv + metrics.json; "
          f"median of {args.repeats} runs (load average {os.getloadavg()[0]:.1f})")
    print(f"{'command':58s} {'wall s':>7s} {'CPU s':>7s} {'min wall':>9s}")
    for name in commands:
        print(f"{name:58s} {statistics.median(walls[name]):7.2f} {statistics.median(cpus[name]):7.2f} {min(walls[name]):9.2f}")

    main_name = next(iter(commands))
    wall, cpu = statistics.median(walls[main_name]), statistics.median(cpus[main_name])
    print("\nratios (pendulab simulate with flags against ...):")
    for name in list(commands)[2:]:
        print(f"  {name:30s} {wall / statistics.median(walls[name]):5.1f}x (wall)  {cpu / statistics.median(cpus[name]):5.1f}x (CPU)")
    share = statistics.median(walls['python -c "import control"']) / wall
    print(f"  importing python-control alone is {100 * share:.0f} % of the command's wall time")
    verdict = "meets" if wall < BAR_S else ("meets by CPU time (wall clock inflated by the load)" if cpu < BAR_S else "MISSES")
    print(f"\nbar < {BAR_S:g} s: {wall:.2f} s wall, {cpu:.2f} s CPU -> {verdict}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
