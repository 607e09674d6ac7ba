#!/usr/bin/env python3
"""A dead or frozen encoder during a lab session: how long until ``lab`` stops the motor.

For each rig (``pendulab rig-emulator``, and the real firmware in its simavr twin with ``--firmware``) and
each fault (``--dead-encoder`` / ``--frozen-encoder``, cart or pendulum, 3 s after the host connects), one
``lab --port PTY --demo --delay 3 --stop-time 10`` session: the pendulum is raised at 0.3 s, the demo
controller holds it, the encoder fails. The time is the rig's own, from its line announcing the fault to
its line announcing the motor off (the rig's clock: the emulator's, or the twin's AVR time). A session that
the watchdog ends first on this shared host is run again (up to three times).

Usage::

    python bench/encoder_faults.py [--rigs emulator,twin]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import threading
import time

PYTHON = sys.executable
ENV = {**os.environ, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1"}
STAMP = re.compile(r"\[(?:rig|twin)\s+([0-9.]+) s\]")
FAULTS = [("--frozen-encoder", "pendulum"), ("--dead-encoder", "pendulum"), ("--frozen-encoder", "cart"), ("--dead-encoder", "cart")]


def one(rig: str, fault: str, which: str) -> tuple[str, float | None]:
    extra = ["--firmware"] if rig == "twin" else []
    emu = subprocess.Popen([PYTHON, "-m", "pendulab", "rig-emulator", *extra, "--raise-after", "0.3", fault, f"{which},3"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    port = emu.stdout.readline().strip()  # type: ignore[union-attr]
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(ln.rstrip() for ln in emu.stderr), daemon=True)  # type: ignore[union-attr]
    reader.start()
    with tempfile.TemporaryDirectory() as tmp:
        result = subprocess.run([PYTHON, "-m", "pendulab", "lab", "--port", port, "--demo", "--delay", "3", "--stop-time", "10",
                                 "--out", f"{tmp}/run"], input="s\n", capture_output=True, text=True, env=ENV, timeout=120)
    time.sleep(0.5)
    emu.terminate()
    emu.wait(10)
    reader.join(2)
    ended = next((ln.split("session ended: ")[1] for ln in result.stdout.splitlines() if "session ended: " in ln), result.stderr.strip())
    failed = [ln for ln in lines if f"{which} encoder" in ln]
    off = [ln for ln in lines if "motor off" in ln]
    if not failed or not off:
        return ended, None
    t_fail = float(STAMP.match(failed[0]).group(1))  # type: ignore[union-attr]
    t_off = [float(STAMP.match(ln).group(1)) for ln in off if STAMP.match(ln)]  # type: ignore[union-attr]
    after = [t for t in t_off if t >= t_fail]
    return ended, (after[0] - t_fail) if after else None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rigs", default="emulator,twin")
    args = parser.parse_args()
    rows = []
    for rig in args.rigs.split(","):
        for fault, which in FAULTS:
            for attempt in range(3):
                ended, delay = one(rig, fault, which)
                if "watchdog" not in ended:
                    break
                print(f"{rig} {fault} {which}: try {attempt + 1} ended by the watchdog first; again", flush=True)
            rows.append((rig, fault, which, ended, delay))
            print(f"{rig:8s} {fault:16s} {which:8s} motor off after {'n/a' if delay is None else f'{delay * 1e3:.0f} ms'}; {ended[:100]}",
                  flush=True)
    print("\n| rig | fault | encoder | motor off after the fault | lab says |")
    print("|---|---|---|---|---|")
    for rig, fault, which, ended, delay in rows:
        print(f"| {rig} | {fault[2:]} | {which} | {'n/a' if delay is None else f'{delay * 1e3:.0f} ms'} | {ended[:90]} |")
    print(f"\nload average: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
