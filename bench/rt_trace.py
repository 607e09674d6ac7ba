#!/usr/bin/env python3
"""Where each period's time goes between ``pendulab rig-emulator`` and its host (``lab`` or ``calibrate``).

Both processes run their normal command with timestamps added from outside (this script wraps a few
methods; the product code is unchanged): per sample, when the emulator sent it, when the host had read
it, when the host's answer was written, when the emulator read that answer's bytes from the pty and when
it handled them, and the emulator's own scheduling (gaps between its ticks). Both clocks are
``time.perf_counter`` (CLOCK_MONOTONIC on Linux), so the legs can be subtracted across the processes.
Printed per run: each leg's p50/p99/max, and for every watchdog trip the legs of the samples in the
``--window`` ms before it, so that it shows which side was late: the emulator (its ticks late), the
pty on the way out (sample sent -> host read), the host (read -> answer written) or the pty on the way
in (answer written -> emulator read).

With ``--ftrace`` (Linux, root) the kernel's scheduler events (sched_switch, sched_wakeup, workqueue
execution) are recorded in a tracefs instance too, and the window before each trip is printed: which
task ran on each core while the answer waited.

Usage::

    python bench/rt_trace.py [--kind lab|calibrate] [--runs 3] [--hog] [--ftrace] [--before COMMIT]
"""

from __future__ import annotations

import argparse
import atexit
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
PYTHON = sys.executable
TRACEFS = Path("/sys/kernel/tracing")


# ---------------------------------------------------------------- inside the traced processes
def _trace_emulator(out: str) -> None:
    from pendulab.hil import protocol as P
    from pendulab.hil.emulator import RigEmulator

    sent: list[tuple[int, int, float]] = []        # (seq, tick, time after the write)
    pulls: list[tuple[float, bytes]] = []           # (time, bytes read from the pty)
    handled: list[tuple[int, float]] = []           # (answers, time) of each COMMAND handled
    ticks: list[tuple[float, float]] = []           # (entry, exit) of each firmware tick
    trips: list[tuple[float, str]] = []
    send, pull, handle, tick, disable = RigEmulator.send, RigEmulator._pull, RigEmulator._handle, RigEmulator._tick, RigEmulator._disable

    def t_send(self, frame):  # type: ignore[no-untyped-def]
        send(self, frame)
        if isinstance(frame, P.Sample):
            sent.append((frame.seq, frame.tick, time.perf_counter()))

    def t_pull(self, now):  # type: ignore[no-untyped-def]
        n = len(self._incoming)
        pull(self, now)
        if len(self._incoming) > n:
            pulls.append((time.perf_counter(), self._incoming[-1][1]))

    def t_handle(self, frame, now):  # type: ignore[no-untyped-def]
        if isinstance(frame, P.Command):
            handled.append((frame.answers, time.perf_counter()))
        handle(self, frame, now)

    def t_tick(self, now):  # type: ignore[no-untyped-def]
        start = time.perf_counter()
        tick(self, now)
        ticks.append((start, time.perf_counter()))

    def t_disable(self, why):  # type: ignore[no-untyped-def]
        if "watchdog" in why:
            trips.append((time.perf_counter(), why))
        disable(self, why)

    RigEmulator.send, RigEmulator._pull, RigEmulator._handle, RigEmulator._tick, RigEmulator._disable = (
        t_send, t_pull, t_handle, t_tick, t_disable)

    def dump() -> None:
        reader = P.FrameReader()
        arrived = []                                  # (answers, time its last byte was read)
        for at, data in pulls:
            arrived += [(f.answers, at) for f in reader.feed(data) if isinstance(f, P.Command)]
        np.savez(out, sent=np.array(sent, float).reshape(-1, 3), arrived=np.array(arrived, float).reshape(-1, 2),
                 handled=np.array(handled, float).reshape(-1, 2), ticks=np.array(ticks, float).reshape(-1, 2),
                 trips=np.array([t for t, _ in trips], float), pid=os.getpid())

    atexit.register(dump)


def _trace_host(out: str) -> None:
    from pendulab.hil.link import RigLink

    received: list[tuple[int, int, float, float, float]] = []   # (seq, tick, asked at, bytes read at, returned at)
    commands: list[tuple[int, float, float]] = []               # (answers, write started, write returned)
    next_sample, command = RigLink.next_sample, RigLink.command

    def t_next_sample(self, timeout):  # type: ignore[no-untyped-def]
        asked = time.perf_counter()
        item = next_sample(self, timeout)
        if item is not None:
            received.append((item[0].seq, item[0].tick, asked, item[1], time.perf_counter()))
        return item

    def t_command(self, answers, voltage, **kw):  # type: ignore[no-untyped-def]
        start = time.perf_counter()
        command(self, answers, voltage, **kw)
        commands.append((answers, start, time.perf_counter()))

    RigLink.next_sample, RigLink.command = t_next_sample, t_command

    def dump() -> None:
        np.savez(out, received=np.array(received, float).reshape(-1, 5), commands=np.array(commands, float).reshape(-1, 3),
                 pid=os.getpid())

    atexit.register(dump)


def _role(role: str, out: str, argv: list[str]) -> int:
    (_trace_emulator if role == "emulator" else _trace_host)(out)
    import runpy

    sys.argv = ["pendulab", *argv]  # 'python -m pendulab ...' in this (traced) process
    try:
        runpy.run_module("pendulab", run_name="__main__", alter_sys=True)
    except SystemExit as exc:
        return int(exc.code or 0) if not isinstance(exc.code, str) else 1
    return 0


# ---------------------------------------------------------------- kernel scheduler trace (optional)
class FTrace:
    """sched_switch / sched_wakeup / workqueue events in a tracefs instance, CLOCK_MONOTONIC stamps."""

    def __init__(self) -> None:
        self.dir = TRACEFS / "instances" / "pendulab_rt"
        if not (TRACEFS / "instances").exists():
            raise SystemExit("no tracefs at /sys/kernel/tracing (mount -t tracefs nodev /sys/kernel/tracing, as root)")
        self.dir.mkdir(exist_ok=True)
        (self.dir / "trace_clock").write_text("mono")
        (self.dir / "buffer_size_kb").write_text("65536")
        for event in ("sched/sched_switch", "sched/sched_wakeup", "workqueue/workqueue_execute_start"):
            (self.dir / "events" / event / "enable").write_text("1")

    def start(self) -> None:
        (self.dir / "trace").write_text("")
        (self.dir / "tracing_on").write_text("1")

    def stop(self) -> list[str]:
        (self.dir / "tracing_on").write_text("0")
        return (self.dir / "trace").read_text().splitlines()

    def close(self) -> None:
        try:
            (self.dir / "tracing_on").write_text("0")
            self.dir.rmdir()
        except OSError:
            pass


def _ftrace_window(lines: list[str], start: float, end: float, pids: dict[int, str]) -> list[str]:
    out = []
    for line in lines:
        if line.startswith("#"):
            continue
        try:
            head, rest = line.split(": ", 1)
            stamp = float(head.split()[-1])
        except (ValueError, IndexError):
            continue
        if start <= stamp <= end:
            cpu = head.split("[")[1].split("]")[0] if "[" in head else "?"
            task = head.split("[")[0].strip()
            out.append(f"    {(stamp - end) * 1e3:+8.3f} ms cpu{cpu} {task[:24]:24s} {rest[:150]}")
    return out


# ---------------------------------------------------------------- the runs and the analysis
def _env(src: Path, fmus: Path | None) -> dict[str, str]:
    env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1", "PYTHONPATH": f"{src}{os.pathsep}{REPO / 'bench'}"}
    if fmus is not None:
        env["PENDULAB_FMU_DIR"] = str(fmus)
    return env


def one_run(kind: str, env: dict[str, str], folder: Path) -> tuple[str, dict, dict]:
    emu_trace, host_trace = folder / "emulator.npz", folder / "host.npz"
    from watchdog_trips import EMULATOR_ARGS, host_command  # (bench/: the same runs as the trip count's)

    me = str(Path(__file__).resolve())
    emu = subprocess.Popen([PYTHON, me, "--role", "emulator", "--trace", str(emu_trace), "--", "rig-emulator", *EMULATOR_ARGS[kind]],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
    port = emu.stdout.readline().strip()  # type: ignore[union-attr]
    try:
        cmd, stdin = host_command(kind, port, folder)
        result = subprocess.run([PYTHON, me, "--role", "host", "--trace", str(host_trace), "--", *cmd], input=stdin,
                                capture_output=True, text=True, env=env, timeout=120)
    finally:
        emu.terminate()
        emu.wait(10)
    text = result.stdout + result.stderr
    lines = [ln for ln in text.splitlines() if "ended" in ln or "error" in ln or "written to" in ln or "Traceback" in ln]
    ending = lines[-1] if lines else (text.strip().splitlines() or ["?"])[-1]
    return ending, dict(np.load(emu_trace)), dict(np.load(host_trace))


def legs(emu: dict, host: dict) -> dict[str, np.ndarray]:
    """Per sample of the last stream: times (s) of each leg, keyed by the sample's tick."""
    sent = emu["sent"]
    last_stream = int(np.flatnonzero(sent[:, 1] == 0)[-1]) if (sent[:, 1] == 0).any() else 0
    sent = sent[last_stream:]
    rec = host["received"]
    rec = rec[rec[:, 2] >= sent[0, 2] - 1.0]
    seq_of_tick = {int(t): int(s) for s, t, _ in sent}
    host_read = {int(t): (asked, read, ret) for s, t, asked, read, ret in rec if seq_of_tick.get(int(t)) == int(s)}
    written = {int(a): end for a, _, end in host["commands"]}
    arrived: dict[int, float] = {}
    for a, at in emu["arrived"]:
        arrived.setdefault(int(a), at)
    handled: dict[int, float] = {}
    for a, at in emu["handled"]:
        handled.setdefault(int(a), at)
    n = len(sent)
    out = {k: np.full(n, np.nan) for k in ("sent", "asked", "read", "returned", "written", "arrived", "handled")}
    out["tick"] = sent[:, 1]
    out["sent"] = sent[:, 2]
    for i, (s, t, _) in enumerate(sent):
        if int(t) in host_read:
            out["asked"][i], out["read"][i], out["returned"][i] = host_read[int(t)]
        # (a sequence number is reused after 65536 frames: take the answer that came after this sample)
        w = written.get(int(s))
        if w is not None and w > sent[i, 2]:
            out["written"][i] = w
            out["arrived"][i] = arrived.get(int(s), np.nan)
            out["handled"][i] = handled.get(int(s), np.nan)
    return out


def _stats(x: np.ndarray) -> str:
    x = x[np.isfinite(x)] * 1e3
    if not x.size:
        return "-"
    return f"p50 {np.percentile(x, 50):6.3f}  p99 {np.percentile(x, 99):6.3f}  max {x.max():7.2f} ms"


def report(kind: str, ending: str, emu: dict, host: dict, window: float, ftrace_lines: list[str] | None) -> None:
    L = legs(emu, host)
    gap = np.diff(L["sent"], prepend=np.nan)
    out_leg = L["read"] - L["sent"]
    host_leg = L["written"] - L["read"]
    in_leg = L["arrived"] - L["written"]
    handle_leg = L["handled"] - L["arrived"]
    print(f"  ended: {ending[:120]}")
    print(f"  {len(L['sent'])} samples; answered {np.isfinite(L['written']).sum()}, arrived {np.isfinite(L['arrived']).sum()}")
    print(f"  emulator tick gap    {_stats(gap)}")
    print(f"  pty out (sent->read) {_stats(out_leg)}")
    print(f"  host (read->written) {_stats(host_leg)}")
    print(f"  pty in (written->emu read) {_stats(in_leg)}")
    print(f"  emu read->handled    {_stats(handle_leg)}")
    for trip in emu["trips"]:
        inside = (L["sent"] > trip - window) & (L["sent"] <= trip)
        print(f"  WATCHDOG TRIP at {trip - L['sent'][0]:.3f} s after the stream began; samples in the {window * 1e3:.0f} ms before:")
        print("      tick   sent(ms) gap    out    host   in     handled  host asked (ms; sent, handled, asked relative to the trip)")
        for i in np.flatnonzero(inside):
            print(f"    {int(L['tick'][i]):6d} {(L['sent'][i] - trip) * 1e3:+8.2f} {gap[i] * 1e3:6.2f} {out_leg[i] * 1e3:6.2f} "
                  f"{host_leg[i] * 1e3:6.2f} {in_leg[i] * 1e3:6.2f} {(L['handled'][i] - trip) * 1e3:+8.2f} {(L['asked'][i] - trip) * 1e3:+8.2f}")
        last = np.nanmax(np.where(L["handled"] <= trip, L["handled"], np.nan)) if np.isfinite(L["handled"]).any() else np.nan
        print(f"    last command handled {(last - trip) * 1e3:+.2f} ms before the trip")
        if ftrace_lines is not None:
            pids = {int(emu["pid"]): "emulator", int(host["pid"]): "host"}
            print("    kernel scheduler events in the window:")
            for line in _ftrace_window(ftrace_lines, trip - window, trip, pids)[-200:]:
                print(line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--role", choices=("emulator", "host"), help=argparse.SUPPRESS)
    parser.add_argument("--trace", help=argparse.SUPPRESS)
    parser.add_argument("--kind", default="lab", choices=("lab", "calibrate"))
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--hog", action="store_true", help="one CPU hog (a busy loop) during the runs")
    parser.add_argument("--ftrace", action="store_true", help="also record the kernel's scheduler events (root)")
    parser.add_argument("--window", type=float, default=30.0, help="ms before a trip to print")
    parser.add_argument("--before", help="trace this commit's code instead of the checkout's (git archive)")
    parser.add_argument("--keep", help="copy each run's traces (and the kernel's) into this folder")
    args, rest = parser.parse_known_args()
    if args.role:
        sys.exit(_role(args.role, args.trace, rest[1:] if rest[:1] == ["--"] else rest))
    hog = subprocess.Popen([PYTHON, "-c", "while True: pass"]) if args.hog else None
    ftrace = FTrace() if args.ftrace else None
    loads: list[float] = []
    stop = threading.Event()
    threading.Thread(target=lambda: [loads.append(os.getloadavg()[0]) for _ in iter(lambda: stop.wait(5), True)], daemon=True).start()
    try:
        with tempfile.TemporaryDirectory(prefix="pendulab-rt-") as tmp:
            if args.before:
                archive = subprocess.run(["git", "-C", str(REPO), "archive", args.before], capture_output=True, check=True).stdout
                subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
                (Path(tmp) / "fmus").mkdir(exist_ok=True)
                env = _env(Path(tmp) / "src", Path(tmp) / "fmus")
                subprocess.run([PYTHON, "-c", "from pendulab.fmu.build import ensure_fmu\n"
                                "for n in ('Plant', 'Controller', 'Supervisor'): ensure_fmu(n)"], env=env, check=True)
            else:
                env = _env(REPO / "src", None)
            for i in range(args.runs):
                folder = Path(tmp) / f"run{i}"
                folder.mkdir()
                if ftrace:
                    ftrace.start()
                ending, emu, host = one_run(args.kind, env, folder)
                lines = ftrace.stop() if ftrace else None
                if args.keep:
                    keep = Path(args.keep) / f"run{i}"
                    keep.mkdir(parents=True, exist_ok=True)
                    for name in ("emulator.npz", "host.npz"):
                        (keep / name).write_bytes((folder / name).read_bytes())
                    if lines is not None:
                        (keep / "ftrace.txt").write_text("\n".join(lines))
                print(f"run {i + 1} ({args.kind}{', before ' + args.before if args.before else ''})")
                report(args.kind, ending, emu, host, args.window / 1e3, lines)
    finally:
        stop.set()
        if hog is not None:
            hog.terminate()
        if ftrace:
            ftrace.close()
    if loads:
        print(f"load average (1 min): median {sorted(loads)[len(loads) // 2]:.1f}, max {max(loads):.1f} on {os.cpu_count()} cores"
              f"{' (plus one CPU hog)' if args.hog else ''}")


if __name__ == "__main__":
    main()
