#!/usr/bin/env python3
"""``calibrate --port`` against ``pendulab rig-emulator``: every way a ramp test ends early keeps what was measured.

For each ending (an amplifier fault, a firmware restart, a stalled link, the port closing, SIGINT, SIGTERM)
one run of ``pendulab calibrate --port PTY --delay 3 --iterations 3 --pendulum none`` against an emulator
that makes it happen about 17 s after the host connects, during the second iteration (an iteration takes
about 13 s). The table gives, per ending:

* the exit status and the ending as calibrate names it;
* the streamed log's last sample against the event, both as the rig's ticks since the ramp test's stream
  started (the event's tick from the emulator's own clock): "kept to" is how far before the event the log
  stops (a negative number: the log holds samples after it);
* the calibration: partial, from how many iterations.

A run that ends before the event for another reason (this host is shared: the real-time link can be lost,
the watchdog trips) is reported and run again, up to three times.

Usage::

    python bench/hil_endings.py [--only fault,SIGTERM]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

PYTHON = sys.executable
ENV = {**os.environ, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1"}
AT = 17.0  # s after the host connects (--at)
STAMP = re.compile(r"\[rig\s+([0-9.]+) s\]")


def endings(at: float) -> dict:
    """ending -> (emulator options, signal sent by the bench or None, the emulator's words for the event, calibrate's)."""
    return {
        "fault": (["--fault-after", str(at)], None, "fault (amplifier", "fault"),
        "restart": (["--restart-after", str(at)], None, "restart: firmware reset", "restarted"),
        "stall": (["--stall-after", str(at), "--stall-for", "0.5"], None, "link stalled", "link lost"),
        "port closed": (["--close-after", str(at)], None, "closing the port", "link lost"),
        "SIGINT": ([], signal.SIGINT, "motor off", "interrupted"),
        "SIGTERM": ([], signal.SIGTERM, "motor off", "SIGTERM"),
    }


def one_run(name: str, folder: Path, at: float = AT) -> dict:
    options, sig, words, named = endings(at)[name]
    emu = subprocess.Popen([PYTHON, "-m", "pendulab", "rig-emulator", "--pendulum", "none", "--friction", "2,0.004,3.5,0.04,25", *options],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    port = emu.stdout.readline().strip()  # type: ignore[union-attr]
    lines: list[str] = []
    import threading

    reader = threading.Thread(target=lambda: lines.extend(ln.rstrip() for ln in emu.stderr), daemon=True)  # type: ignore[union-attr]
    reader.start()
    out = folder / "c.json"
    cal = subprocess.Popen([PYTHON, "-m", "pendulab", "calibrate", "--port", port, "--delay", "3", "--iterations", "3", "--pendulum", "none",
                            "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    if sig is not None:
        deadline = time.monotonic() + 30
        while not any("host connected" in ln for ln in lines) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(at)
        cal.send_signal(sig)
    stdout, stderr = cal.communicate(timeout=120)
    time.sleep(0.5)
    emu.terminate()
    emu.wait(10)
    reader.join(2)
    result = {"ending": name, "status": cal.returncode, "stdout": stdout, "stderr": stderr}
    ended = [ln for ln in stdout.splitlines() if "ended early" in ln or "stopped by" in ln]
    result["named"] = ended[0] if ended else (stderr.strip().splitlines() or ["?"])[-1]
    events = [ln for ln in lines if words in ln]
    log = folder / "c-log.csv"
    if events and log.is_file():
        event = float(STAMP.match(events[-1]).group(1))  # type: ignore[union-attr]
        starts = [float(STAMP.match(ln).group(1)) for ln in lines if "streaming samples" in ln and STAMP.match(ln)]  # type: ignore[union-attr]
        start = max(s for s in starts if s <= event)
        data = np.genfromtxt(log, delimiter=",", names=True)
        result["kept_to_ms"] = (event - start) * 1000.0 - float(data["tick"][-1])
        result["samples"] = int(data.size)
    if out.is_file():
        meta = json.loads(out.read_text()).get("metadata", {})
        result["calibration"] = f"partial, {meta.get('iterations')} of {meta.get('iterations_planned')}" if meta.get("partial") else "complete"
    else:
        result["calibration"] = "none"
    # The host is shared: its real-time link may be lost (watchdog, a stall of this machine) before the event.
    result["watchdog_first"] = named not in result["named"]
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", help="comma-separated endings")
    parser.add_argument("--at", type=float, default=AT, help=f"s after the host connects (default {AT:g}: in the second iteration)")
    args = parser.parse_args()
    names = args.only.split(",") if args.only else list(endings(args.at))
    rows = []
    for name in names:
        for attempt in range(3):
            with tempfile.TemporaryDirectory() as tmp:
                result = one_run(name, Path(tmp), args.at)
            if not result["watchdog_first"] or name == "watchdog":
                break
            print(f"{name}: try {attempt + 1} ended before the event ({result['named'][:100]}); again", flush=True)
        rows.append(result)
        print(f"{name}: status {result['status']}, kept to {result.get('kept_to_ms', float('nan')):.0f} ms of the event, "
              f"calibration {result['calibration']}; {result['named']}", flush=True)
    print("\n| ending | exit | log kept to (ms before the event) | calibration | calibrate says |")
    print("|---|---|---|---|---|")
    for r in rows:
        kept = f"{r['kept_to_ms']:.0f}" if "kept_to_ms" in r else "n/a"
        print(f"| {r['ending']} | {r['status']} | {kept} | {r['calibration']} | {r['named'][:110]} |")
    with os.popen("uptime") as up:
        print(f"\nhost: {up.read().strip()}")


if __name__ == "__main__":
    main()
