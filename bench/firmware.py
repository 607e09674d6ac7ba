#!/usr/bin/env python3
"""The rig firmware in its simavr twin: simulation speed against real time, interrupt cost, CPU load.

Bars (issue 9): the twin runs at >= 1x real time with the plant and the encoders attached (so it can be
paced to real time); the firmware's CPU load at the largest encoder rates (cart 1.5 m/s, pendulum
20 rad/s) is <= 50 %.

Cases, all on the same firmware and twin build:

* ``bare``: the twin unpaced, plant at rest, no host (simavr running the idle firmware; the baseline);
* ``encoders``: unpaced, the encoders driven at 1.5 m/s and 20 rad/s (about 79 000 edges per second);
* ``session``: paced to real time, the encoders at full rate, a host streaming at 1 kHz and answering
  every sample (the worst case for the firmware). Its speed capacity is AVR time over the twin's
  CPU time (how much faster than real time it could go); the CPU load is from simavr's cycle count
  (cycles not asleep); the interrupts' worst cases are in cycles.

Usage::

    python bench/firmware.py [--seconds 10]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def unpaced(args: list[str], seconds: float, profile: Path) -> dict:
    from pendulab.hil.firmware import build_firmware, build_twin
    from pendulab.model.parameters import PlantParameters

    params = ",".join(repr(v) for v in PlantParameters.preset().as_vector())
    from pendulab.hil.firmware import idle_loop_range

    command = [str(build_twin()), str(build_firmware()), "--params", params, "--no-pace", "--duration", str(seconds),
               "--profile", str(profile), "--idle", "%d,%d" % idle_loop_range(), *args]
    subprocess.run(command, capture_output=True, text=True, check=True)
    return json.loads(profile.read_text())


def session(seconds: float, profile: Path) -> dict:
    from firmware_helpers import twin

    from pendulab.hil.firmware import idle_loop_range
    from pendulab.hil.link import RigLink

    with twin("--kinematic", f"1.5,20,{seconds + 2}", "--idle", "%d,%d" % idle_loop_range(), profile=profile) as t, RigLink.open(t.port) as link:
        link.identify()
        link.configure(delay=3, x_limit=1.0)
        link.stream(True)
        for k in range(int(seconds * 1000)):
            item = link.next_sample(0.5)
            if item is None:
                raise RuntimeError("the twin stopped sending samples")
            link.command(item[0].seq, 0.0, enable=False, clear=k == 0)
        link.stream(False)
    return json.loads(profile.read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        bare = unpaced([], args.seconds, Path(tmp) / "bare.json")
        enc = unpaced(["--kinematic", f"1.5,20,{args.seconds}"], args.seconds, Path(tmp) / "enc.json")
        live = session(args.seconds, Path(tmp) / "session.json")
    print(f"{'case':<10} {'AVR s':>7} {'wall s':>7} {'CPU s':>7} {'x real time':>12} {'edges/s':>9} {'awake':>7} {'load':>7}")
    for name, p in (("bare", bare), ("encoders", enc), ("session", live)):
        speed = p["avr_s"] / max(p["cpu_s"], 1e-9)
        awake = 1 - p["sleep_cycles"] / p["cycles"]
        load = 1 - (p["sleep_cycles"] + p["idle_loop_cycles"]) / p["cycles"]
        print(f"{name:<10} {p['avr_s']:7.2f} {p['wall_s']:7.2f} {p['cpu_s']:7.2f} {speed:11.1f}x {p['edges'] / p['avr_s']:9.0f} "
              f"{100 * awake:6.1f}% {100 * load:6.1f}%")
    print("awake: cycles not asleep; load: awake minus the idle loop's re-arming after each interrupt (what a")
    print("polling idle loop would spend idle). Unpaced cases have no host, so no UART traffic.")
    print(f"encoders vs bare: {enc['cpu_s'] / enc['avr_s'] / (bare['cpu_s'] / bare['avr_s']):.1f}x the CPU per AVR second")
    isr = {int(k): v for k, v in live["isr"].items()}
    names = {1: "INT0 cart A", 2: "INT1 cart B", 3: "INT2 pendulum A", 4: "INT3 pendulum B", 17: "TIMER1_COMPA tick",
             25: "USART0_RX", 26: "USART0_UDRE"}
    print("interrupts in the session (cycles at 16 MHz; the tick's includes the encoder interrupts nested in it):")
    for v in sorted(isr):
        s = isr[v]
        print(f"  {names.get(v, v)!s:<20} count {s['count']:8d}  mean {s['total'] / s['count']:7.1f}  worst {s['max']:6d}")
    print(f"  encoder interrupt latency, worst: {max(live['encoder_latency_max'])} cycles "
          f"(an edge is missed above 243: 15.2 us between cart edges at 1.5 m/s)")
    load = 1 - (live["sleep_cycles"] + live["idle_loop_cycles"]) / live["cycles"]
    capacity = live["avr_s"] / live["cpu_s"]
    print(f"verdict: speed capacity {capacity:.1f}x real time (bar >= 1x): {'PASS' if capacity >= 1 else 'FAIL'}; "
          f"CPU load at full encoder rate with the host streaming {100 * load:.1f} % (bar <= 50 %): {'PASS' if load <= 0.5 else 'FAIL'}")


if __name__ == "__main__":
    main()
