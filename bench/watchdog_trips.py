#!/usr/bin/env python3
"""Watchdog trips of ``calibrate --port`` and ``lab`` against ``pendulab rig-emulator``, before and after.

``calibrate --port`` used to run without ``lab``'s real-time measures (no raised priority, the garbage
collector free to stop its loop while the ramp log grows), and the emulator counted its own stalls (this
process not scheduled for tens of ms on a busy host) against the host. Each run counts as a trip when it
ends with "watchdog tripped" before its natural end:

* calibrate: ``calibrate --port PTY --delay 3 --iterations 1 --pendulum none`` (about 14 s of ramps) against
  ``rig-emulator --pendulum none``;
* lab: ``lab --port PTY --demo --delay 3 --stop-time 12`` against ``rig-emulator --raise-after 0.3``.

"before" runs the code of a given commit (``git archive`` into a temporary folder, its FMUs built there),
"after" this checkout; the two alternate run by run, so that both see the same load. The load average
is printed: the figures say as much about the host as about the code.

Usage::

    python bench/watchdog_trips.py [--runs 20] [--before 2bb46a2] [--hog]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PYTHON = sys.executable


def _env(src: Path, fmus: Path | None) -> dict[str, str]:
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1", "PYTHONPATH": str(src)}
    if fmus is not None:
        env["PENDULAB_FMU_DIR"] = str(fmus)
    return env


#: The rig emulator's options for each kind of run (bench/rt_trace.py runs the same).
EMULATOR_ARGS = {"calibrate": ["--pendulum", "none"], "lab": ["--raise-after", "0.3"]}


def host_command(kind: str, port: str, folder: Path) -> tuple[list[str], str | None]:
    """The host's ``pendulab`` arguments and its stdin for one calibrate or lab run against ``port``."""
    if kind == "calibrate":
        return ["calibrate", "--port", port, "--delay", "3", "--iterations", "1", "--pendulum", "none", "--out", str(folder / "c.json")], None
    return ["lab", "--port", port, "--demo", "--delay", "3", "--stop-time", "12", "--out", str(folder / "lab")], "s\n"


def one_run(kind: str, env: dict[str, str], folder: Path) -> tuple[bool, str, float]:
    """(tripped, ending line, seconds) of one calibrate or lab run."""
    emu = subprocess.Popen([PYTHON, "-m", "pendulab", "rig-emulator", *EMULATOR_ARGS[kind]], stdout=subprocess.PIPE,
                           stderr=subprocess.DEVNULL, text=True, env=env)
    port = emu.stdout.readline().strip()  # type: ignore[union-attr]
    started = time.monotonic()
    try:
        cmd, stdin = host_command(kind, port, folder)
        result = subprocess.run([PYTHON, "-m", "pendulab", *cmd], input=stdin, capture_output=True, text=True, env=env, timeout=120)
    finally:
        emu.terminate()
        emu.wait(10)
    text = result.stdout + result.stderr
    tripped = "watchdog tripped" in text
    lines = [ln for ln in text.splitlines() if "ended" in ln or "error" in ln or "written to" in ln]
    ending = lines[-1] if lines else (text.strip().splitlines() or ["?"])[-1]
    return tripped, ending, time.monotonic() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--before", default="2bb46a2", help="commit of the 'before' code")
    parser.add_argument("--kinds", default="calibrate,lab")
    parser.add_argument("--hog", action="store_true", help="also run one CPU hog (a busy loop) during the runs")
    args = parser.parse_args()
    kinds = args.kinds.split(",")
    hog = subprocess.Popen([PYTHON, "-c", "while True: pass"]) if args.hog else None
    loads: list[float] = []
    stop = threading.Event()

    def sample_load() -> None:
        while not stop.wait(5):
            loads.append(os.getloadavg()[0])

    threading.Thread(target=sample_load, daemon=True).start()
    try:
        with tempfile.TemporaryDirectory(prefix="pendulab-before-") as tmp:
            before_src = Path(tmp) / "src"
            archive = subprocess.run(["git", "-C", str(REPO), "archive", args.before], capture_output=True, check=True).stdout
            subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
            (Path(tmp) / "fmus").mkdir(exist_ok=True)
            setups = {"before": _env(before_src, Path(tmp) / "fmus"), "after": _env(REPO / "src", None)}
            for name, env in setups.items():  # build the FMUs first, not inside a timed run
                subprocess.run([PYTHON, "-c", "from pendulab.fmu.build import ensure_fmu\n"
                                "for n in ('Plant', 'Controller', 'Supervisor'): ensure_fmu(n)"], env=env, check=True)
            counts = {(k, s): [0, 0] for k in kinds for s in setups}
            for i in range(args.runs):
                for kind in kinds:
                    for name, env in setups.items():
                        with tempfile.TemporaryDirectory() as folder:
                            tripped, ending, seconds = one_run(kind, env, Path(folder))
                        counts[(kind, name)][0] += tripped
                        counts[(kind, name)][1] += 1
                        print(f"{i + 1:2d} {kind:9s} {name:6s} {'TRIP' if tripped else 'ok  '} {seconds:5.1f} s  {ending[:110]}", flush=True)
    finally:
        stop.set()
        if hog is not None:
            hog.terminate()
    print("\n| runs | before: trips | after: trips |")
    print("|---|---|---|")
    for kind in kinds:
        b, a = counts[(kind, "before")], counts[(kind, "after")]
        print(f"| {kind} | {b[0]} of {b[1]} | {a[0]} of {a[1]} |")
    if loads:
        print(f"\nload average (1 min) during the runs: median {sorted(loads)[len(loads) // 2]:.1f}, max {max(loads):.1f} "
              f"on {os.cpu_count()} cores{' (plus one CPU hog)' if args.hog else ''}")


if __name__ == "__main__":
    main()
