"""The real-time link's clocks, in process and deterministic (issue 26's leftovers).

* The rig emulator's watchdog counts the host's time only: a stall of the emulator itself (this process not
  running: a loaded host) never trips it, however long and wherever it happens; a host that stops answering
  still trips it after the watchdog time. Run on a simulated clock, so the stall is exact and nothing waits.
* The host's writes: a full pseudo-terminal whose peer is briefly not reading is not a lost link; a port that
  takes no byte at all is, in one line.
* The host's reads: samples that arrived while the host itself was not running are read before their absence
  is taken for silence.
"""

from __future__ import annotations

import os
import sys
import threading
import time

import pytest

from pendulab.hil import emulator as emulator_module
from pendulab.hil import link as link_module
from pendulab.hil import protocol as P


class SimulatedTime:
    """``time`` for the emulator: the clock moves by sleeping, by a small step per reading, and by injected stalls."""

    def __init__(self) -> None:
        self.now = 1000.0
        self.reads = 0

    def perf_counter(self) -> float:
        self.reads += 1
        self.now += 20e-6  # (a spin loop that reads the clock makes progress)
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += max(seconds, 0.0)


class Host:
    """Answers each SAMPLE 0.3 ms after the emulator sent it (a quick host), until ``answer_until`` samples."""

    def __init__(self, clock: SimulatedTime, answer_until: int | None = None, answer_after: float = 3e-4) -> None:
        self.clock, self.answer_until, self.answer_after = clock, answer_until, answer_after
        self.reader = P.FrameReader()
        self.pending: list[tuple[float, bytes]] = []
        self.samples: list[P.Sample] = []

    def write(self, data: bytes) -> None:  # the emulator -> the host
        for frame in self.reader.feed(data):
            if isinstance(frame, P.Sample):
                self.samples.append(frame)
                if self.answer_until is None or len(self.samples) <= self.answer_until:
                    command = P.Command(len(self.samples) & 0xFFFF, answers=frame.seq, voltage_mv=1000, flags=P.ENABLE)
                    self.pending.append((self.clock.now + self.answer_after, P.encode(command)))

    def read(self) -> bytes:  # what has reached the emulator by now
        due = [data for at, data in self.pending if at <= self.clock.now]
        self.pending = [(at, data) for at, data in self.pending if at > self.clock.now]
        return b"".join(due)


def _emulator_run(monkeypatch, *, stall_before_sample: int | None, answer_until: int | None, seconds: float = 0.4,
                  tick_cost: float = 0.0, answer_after: float = 3e-4, delay: int = 4):
    """A configured, streaming emulator (N = ``delay``, watchdog 20 ms) on the simulated clock; the emulator itself is
    held for 80 ms just before it sends sample ``stall_before_sample``, and for ``tick_cost`` s before every sample."""
    clock = SimulatedTime()
    monkeypatch.setattr(emulator_module, "time", clock)
    lines: list[str] = []
    emu = emulator_module.RigEmulator(emulator_module.EmulatorOptions(), announce=lines.append)
    host = Host(clock, answer_until, answer_after)
    emu._read, emu._write = host.read, host.write
    sent = 0
    real_send = emu.send

    def send(frame):
        nonlocal sent
        if isinstance(frame, P.Sample):
            sent += 1
            clock.now += tick_cost
            if sent == stall_before_sample:
                clock.now += 0.080  # the OS does not run the emulator for 80 ms
        real_send(frame)

    emu.send = send
    try:
        emu._handle(P.Configure(0, period_us=1000, watchdog_ms=20, delay=delay, x_min=-20000, x_max=20000, v_max_mv=10000), 0.0)
        emu._handle(P.Stream(1, on=1), 0.0)
        emu.run(seconds)
    finally:
        emu.close()
    return emu, host, lines


def test_a_stall_of_the_emulator_itself_does_not_trip_its_watchdog(monkeypatch):
    emu, host, lines = _emulator_run(monkeypatch, stall_before_sample=150, answer_until=None)
    assert len(host.samples) > 300
    tripped = [line for line in lines if "watchdog tripped" in line]
    # (before the fix: tripped at the first tick after the stall, the host having had nothing to answer for 80 ms)
    assert not tripped, tripped
    assert not any(s.status & P.ST_WATCHDOG for s in host.samples)
    assert host.samples[-1].voltage_mv == 1000 and host.samples[-1].status & P.ST_ENABLED


def test_a_host_that_stops_answering_still_trips_the_watchdog_after_20_ms(monkeypatch):
    emu, host, lines = _emulator_run(monkeypatch, stall_before_sample=150, answer_until=250)
    assert any("watchdog tripped" in line for line in lines)
    first = next(k for k, s in enumerate(host.samples) if s.status & P.ST_WATCHDOG)
    # The last answer reached the rig with sample 251's tick; 0 V from the first tick 20 ms after it.
    assert 250 + 19 <= first <= 250 + 23, first
    assert host.samples[first].voltage_mv == 0 and not host.samples[first].status & P.ST_ENABLED


def test_an_emulator_that_stays_behind_its_schedule_still_trips_on_a_silent_host(monkeypatch):
    """Each tick costs 1.05 periods (an overloaded emulator): its lateness grows by 50 us a tick, which is credited,
    and the silent host is still given 20 ms of the rig's time only (crediting the whole lateness again at every
    tick, as before, gave it forever: no trip in 0.4 s)."""
    emu, host, lines = _emulator_run(monkeypatch, stall_before_sample=None, answer_until=250, tick_cost=1.05e-3)
    first = next((k for k, s in enumerate(host.samples) if s.status & P.ST_WATCHDOG), None)
    assert first is not None, "the watchdog never tripped"
    assert 250 + 19 <= first <= 250 + 23, first


def test_the_emulator_sleeps_while_it_waits_for_a_late_answer(monkeypatch):
    """Answers come 1.5 periods after each sample at N = 1: every tick waits for its answer until the deadline.
    It must sleep there (select/sleep), not spin on the clock: a spinning SCHED_FIFO emulator keeps a core from
    the kernel worker that moves the pty's bytes, the very answer it waits for (traced: bench/rt_trace.py)."""
    emu, host, lines = _emulator_run(monkeypatch, stall_before_sample=None, answer_until=None, answer_after=1.5e-3,
                                     delay=1, seconds=0.2)
    ticks = len(host.samples)
    reads = emulator_module.time.reads  # (the simulated clock, counting)
    assert ticks > 100
    # A spin reads the clock every 20 us of waiting (some 50 reads per tick here); sleeping, a handful.
    assert reads / ticks < 15, reads / ticks


# ---------------------------------------------------------------- the host's writes and reads
pty_only = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")


@pty_only
def test_a_full_pseudo_terminal_whose_peer_reads_again_is_not_a_lost_link():
    import pty
    import tty

    master, slave = pty.openpty()
    tty.setraw(slave)
    link = link_module.RigLink.open(os.ttyname(slave))
    read: list[bytes] = []
    reader = threading.Timer(0.8, lambda: read.append(os.read(master, 1 << 20)))  # the peer reads again 0.8 s later
    try:
        os.set_blocking(link.port.fileno(), False)
        filled = 0
        while True:  # the rig's side reads nothing for now: fill the buffer to the brim
            try:
                filled += os.write(link.port.fileno(), b"\0" * 256)
            except BlockingIOError:
                # (the kernel's worker may still move bytes into the peer's read buffer, making room: full
                # only when a fill 50 ms later finds none)
                time.sleep(0.05)
                try:
                    filled += os.write(link.port.fileno(), b"\0" * 256)
                except BlockingIOError:
                    break
        reader.start()
        started = time.perf_counter()
        link.command(7, 1.0, enable=True)  # pyserial's write_timeout of 0.5 s called this "link lost (Write timeout)"
        waited = time.perf_counter() - started
        reader.join()
        print(f"buffer {filled} bytes; the command waited {waited:.2f} s for the peer")
        assert 0.6 < waited < link_module.WRITE_STALL
        assert read and len(read[0]) > 0
    finally:
        reader.cancel()
        reader.join()
        link.close()
        os.close(master)
        os.close(slave)


@pty_only
def test_a_port_that_takes_no_byte_is_a_lost_link_in_one_line(monkeypatch):
    import pty
    import tty

    monkeypatch.setattr(link_module, "WRITE_STALL", 0.2)
    master, slave = pty.openpty()
    tty.setraw(slave)
    link = link_module.RigLink.open(os.ttyname(slave))
    try:
        with pytest.raises(link_module.LinkLost) as lost:
            for _ in range(100_000):  # nobody ever reads
                link.command(1, 0.0, enable=False)
        text = str(lost.value)
        assert "\n" not in text and text.startswith("link lost: writing to") and "took no byte for 0.2 s" in text
    finally:
        link.close()
        os.close(master)
        os.close(slave)


def test_samples_that_arrived_while_the_host_was_not_running_are_read_before_silence():
    import serial

    link = link_module.RigLink(serial.serial_for_url("loop://", timeout=0.05), "loop://")
    link.send(P.Sample, tick=41, cart=3, voltage_mv=250)  # (loop://: what is written comes back)
    # A host that comes back after its deadline (timeout 0) still finds the sample that is waiting.
    item = link.next_sample(0.0)
    assert item is not None and item[0].tick == 41 and item[0].cart == 3
    assert link.next_sample(0.0) is None  # and nothing else
