"""The rig emulator: Plant.fmu (or Seesaw.fmu) behind a serial port, speaking protocol v1 in real time.

It is a rig as ``docs/protocol.md`` describes one: its own clock samples the encoders every period,
the answer to sample k is applied at tick k + N, the watchdog drops the motor to 0 V, the track
limits are enforced, the encoders are quantized 16-bit counters that wrap. Around it, what a person
and a real link do: the pendulum hangs at start and is raised by hand (``raise_after``), a poke, link
latency and jitter, byte errors, a restart, a stall, the port closing.

The seesaw (``plant="seesaw"``) is the same rig with Seesaw.fmu: its pivot encoder is on the pendulum's
channel, 3 x 4096 counts per turn of the seesaw (the 3:1 gear, in the IDENTITY's counts per rad), 0 = level.
It rests on a tilt stop at start; the hand (``raise_after``) lifts it level and holds it there until the
controller has it, as it raises the pendulum.

Examples
--------
>>> from pendulab.hil.emulator import EmulatorOptions, RigEmulator
>>> # skipped: opens a pseudo-terminal and runs in real time until stopped (tests/test_hil_*.py run it)
>>> emulator = RigEmulator(EmulatorOptions(raise_after=1.0))       # doctest: +SKIP
>>> print(emulator.open_pty())                                     # doctest: +SKIP
/dev/pts/7
>>> emulator.run()                                                 # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
import random
import select
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

from pendulab.hil import protocol as P
from pendulab.hil.realtime import no_garbage_collection
from pendulab.model.parameters import PlantParameters

FIRMWARE_VERSION = (1, 0, 0)
#: Answers kept for the transport delay (protocol: at least max_delay + 1 slots).
RING = 16
#: The rig's own track limit before the host configures one (m from the zero).
DEFAULT_TRACK_LIMIT = 0.45
#: The angle from upright (rad) at which the person holds the pendulum until the controller has it.
HOLD_ANGLE = math.radians(0.5)
#: The hand levels the held seesaw again every this many periods (a restart costs ~20 steps; between two it
#: tilts by far less than one encoder count).
HOLD_EVERY = 20
#: The plants a rig can be: the FMU, its state variables, the parameters' tap (poke) names, the angle at which the
#: hand holds it, and the encoder's zero in the model's angle (the pendulum's reads 0 hanging, the seesaw's 0 level).
PLANTS: dict[str, dict[str, Any]] = {
    "pendulum": {"fmu": "Plant", "state": ("x", "xdot", "alpha", "alphadot"), "poke": "poke", "q": "q_alpha",
                 "hold": HOLD_ANGLE, "encoder_zero": math.pi, "gear": 1, "what": "pendulum"},
    "seesaw": {"fmu": "Seesaw", "state": ("x", "xdot", "theta", "thetadot"), "poke": "tap", "q": "q_theta",
               "hold": 0.0, "encoder_zero": 0.0, "gear": 3, "what": "seesaw"},
}


@dataclass
class EmulatorOptions:
    """What the emulated rig is, and what happens around it.

    Times ``raise_after``, ``restart_after``, ``stall_after`` and ``close_after`` count from the
    moment the host connects (its first IDENTIFY); the poke's start counts from the moment the
    controller takes the pendulum (the first enabled command after the raise).
    """

    params: Any = field(default_factory=PlantParameters.preset)   # PlantParameters, or SeesawParameters for the seesaw
    plant: str = "pendulum"       # "pendulum" (Plant.fmu) or "seesaw" (Seesaw.fmu)
    period: float = 1e-3
    raise_after: float | None = None
    poke: tuple[float, float, float] | None = None
    latency: float = 0.0          # s, added to the host -> rig direction (the round trip grows by it)
    jitter: float = 0.0           # s, uniform +- on that latency
    byte_error_rate: float = 0.0  # probability that a byte (either direction) has one bit flipped
    restart_after: float | None = None
    stall_after: float | None = None
    stall_for: float = 0.5
    close_after: float | None = None
    fault_after: float | None = None
    #: Encoder faults: ``{"cart"|"pendulum": (kind, after)}``, kind "dead" (lost power or cable: the count stops
    #: after one last step towards zero of its quadrature phase) or "frozen" (the disc stuck: the count holds).
    encoder_faults: dict[str, tuple[str, float]] = field(default_factory=dict)
    cart_step: float = 22.75e-6                  # m per count
    pendulum_counts_per_rev: int = 4096
    seed: int | None = None


class _Plant:
    """Plant.fmu (or Seesaw.fmu) as a :class:`~pendulab.cosim.component.Component`; a hand can set its state (a restart)."""

    def __init__(self, params: Any, period: float, state: tuple[float, float, float, float], kind: str = "pendulum") -> None:
        from pendulab.cosim.component import Component
        from pendulab.fmu.build import ensure_fmu

        self.STATE = PLANTS[kind]["state"]
        self.inst = Component("plant", ensure_fmu(PLANTS[kind]["fmu"]), params.as_dict())
        self.inst.setup(0.0, dict(zip(self.STATE, state)))
        self.params = params
        self.period = period
        self.t = 0.0
        self._v = self.inst.port(["V"])
        self._state = self.inst.port([*self.STATE, "V_applied"])

    def restart(self, t: float, state: tuple[float, float, float, float], **changes: float) -> None:
        """Initialize again at time ``t`` in ``state`` (x, xdot, alpha, alphadot), parameters changed by ``changes``."""
        self.inst.reset(t, {**changes, **dict(zip(self.STATE, state))})
        self.t = t

    def step(self, voltage: float) -> None:
        self._v.values["Real"][0] = voltage
        self.inst.write(self._v)
        self.inst.step(self.t, self.period)
        self.t += self.period

    def state(self) -> tuple[float, float, float, float, float]:
        self.inst.read(self._state)
        return tuple(self._state.values["Real"])  # type: ignore[return-value]

    def close(self) -> None:
        self.inst.close()


class RigEmulator:
    """One emulated rig. Call :meth:`open_pty` (or give ``read``/``write`` functions), then :meth:`run`."""

    def __init__(self, options: EmulatorOptions, *, announce: Callable[[str], None] | None = None) -> None:
        self.o = options
        if not 0 <= options.byte_error_rate < 1:
            raise ValueError("byte error rate must be in [0, 1)")
        self.rng = random.Random(options.seed)
        self.announce_line = announce or (lambda text: print(text, file=sys.stderr, flush=True))
        if options.plant not in PLANTS:
            raise ValueError(f"plant {options.plant!r} is not one of {', '.join(PLANTS)}")
        self.kind = PLANTS[options.plant]
        params = options.params.with_values(**{self.kind["q"]: 0.0, "q_x": 0.0, self.kind["poke"] + "_magnitude": 0.0})
        # The pendulum hangs at rest, the seesaw rests on its tilt stop (the -x end down); the cart at the centre.
        rest = math.pi if options.plant == "pendulum" else -params.theta_stop
        self.plant = _Plant(params, options.period, (0.0, 0.0, rest, 0.0), options.plant)
        self.counts_per_m = 1.0 / options.cart_step
        # The seesaw's encoder turns 3 times per turn of the seesaw (its gear): more counts per rad of tilt.
        self.counts_per_rad = self.kind["gear"] * options.pendulum_counts_per_rev / (2 * math.pi)
        self.fd: int | None = None
        self._slave_fd: int | None = None
        self._read: Callable[[], bytes] | None = None
        self._fileno: int | None = None
        self._clock: Callable[[], float] | None = None  # seconds since run() began
        self._write: Callable[[bytes], None] | None = None
        self._stop = False
        self.connected_at: float | None = None
        self._last_counts: dict[str, int] = {}
        self._failed: dict[str, int] = {}
        self.held = False
        self.raised = False
        self._boot()

    # ------------------------------------------------------------------ set-up
    def _boot(self) -> None:
        """Power-on or reset state of the firmware: not streaming, 0 V, a new boot id."""
        self.boot_id = self.rng.getrandbits(32)
        self.seq = 0
        self.streaming = False
        self.period_us = int(round(self.o.period * 1e6))
        self.watchdog_ms = 20
        self.delay = 1
        self.x_min = -int(DEFAULT_TRACK_LIMIT * self.counts_per_m)
        self.x_max = int(DEFAULT_TRACK_LIMIT * self.counts_per_m)
        self.v_max_mv = 10000
        self.zero_cart = 0
        self.zero_pend = 0
        self.tick = 0
        self.voltage = 0.0
        self.enabled = False
        self.wd_tripped = False
        self.limit_hit = False
        self.fault = False
        self.late = 0
        self.applied = 0
        self.last_command_time: float | None = None
        self.ring: list[P.Command | None] = [None] * RING
        self.sample_seqs: deque[int] = deque(maxlen=RING)
        self.sent_at: deque[float] = deque(maxlen=RING)
        self.reader = P.FrameReader()
        self._incoming: deque[tuple[float, bytes]] = deque()
        self._last_delivery = 0.0

    def open_pty(self) -> str:
        """Create the pseudo-terminal and return the path a host opens (POSIX only)."""
        import pty
        import tty

        master, slave = pty.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        self.fd, self._slave_fd = master, slave  # the slave stays open here so the master never sees EIO
        self._fileno = master
        self.path = os.ttyname(slave)

        def read() -> bytes:
            try:
                return os.read(master, 4096)
            except BlockingIOError:
                return b""

        def write(data: bytes) -> None:
            view = memoryview(data)
            while view:
                try:
                    n = os.write(master, view)
                    view = view[n:]
                except BlockingIOError:
                    # Nobody reads the port (host gone): drop, as a UART with no listener does.
                    return

        self._read, self._write = read, write
        return self.path

    def use_socket(self, sock: Any) -> None:
        """Serve one connected TCP socket instead of a pty (the Windows path: ``socket://HOST:PORT``)."""
        sock.setblocking(False)
        self._fileno = sock.fileno()

        def read() -> bytes:
            try:
                data = sock.recv(4096)
            except BlockingIOError:
                return b""
            if not data:
                raise ConnectionError("the host closed the connection")
            return data

        def write(data: bytes) -> None:
            try:
                sock.sendall(data)
            except (BlockingIOError, OSError):
                pass

        self._read, self._write = read, write

    def close(self) -> None:
        for fd in (self.fd, self._slave_fd):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.fd = self._slave_fd = None
        self.plant.close()

    def stop(self) -> None:
        self._stop = True

    # ------------------------------------------------------------------ announcements
    def say(self, text: str) -> None:
        self.announce_line(f"[rig {self.plant.t:8.3f} s] {text}")

    # ------------------------------------------------------------------ link
    def _corrupt(self, data: bytes) -> bytes:
        p = self.o.byte_error_rate
        if p <= 0 or not data:
            return data
        out = bytearray(data)
        for i in range(len(out)):
            if self.rng.random() < p:
                out[i] ^= 1 << self.rng.randrange(8)
        return bytes(out)

    def send(self, frame: P.Frame) -> None:
        assert self._write is not None
        self._write(self._corrupt(P.encode(frame)))

    def _next_seq(self) -> int:
        s = self.seq
        self.seq = (self.seq + 1) & 0xFFFF
        return s

    def _pull(self, now: float) -> None:
        """Read what the host wrote; it reaches the firmware after the link's latency (in order)."""
        assert self._read is not None
        data = self._read()
        if data:
            delay = self.o.latency + (self.rng.uniform(-self.o.jitter, self.o.jitter) if self.o.jitter else 0.0)
            at = max(now + max(delay, 0.0), self._last_delivery)
            self._last_delivery = at
            self._incoming.append((at, self._corrupt(data)))

    def _wait_for_bytes(self, until: float) -> bool:
        """Sleep until the host's bytes come (or bytes already read cross the link's latency), at most to ``until``.

        Blocking, not spinning: at a real-time priority a spinning emulator keeps a core from the kernel
        workers that deliver the pty's bytes, the very bytes it waits for. False once ``until`` has passed.
        """
        assert self._clock is not None
        left = until - self._clock()
        if left <= 0:
            return False
        if self._incoming:  # bytes in flight on an emulated latency: wake when the next crosses
            left = min(left, max(0.0, self._incoming[0][0] - self._clock()))
        if self._fileno is None:
            time.sleep(left)
        else:
            select.select([self._fileno], [], [], left)
        return True

    def _receive(self, now: float) -> list[P.Frame]:
        """Frames whose bytes have crossed the link by ``now``."""
        self._pull(now)
        frames: list[P.Frame] = []
        while self._incoming and self._incoming[0][0] <= now:
            frames += self.reader.feed(self._incoming.popleft()[1])
        return frames

    # ------------------------------------------------------------------ the firmware's logic
    def _handle(self, frame: P.Frame, now: float) -> None:
        if isinstance(frame, P.Identify):
            if self.connected_at is None:
                self.connected_at = now
                self.say("host connected")
            self.send(P.Identity(
                self._next_seq(), P.PROTOCOL_VERSION, *FIRMWARE_VERSION, self.boot_id, self.period_us,
                self.counts_per_m, self.counts_per_rad, self.v_max_mv, self.x_min, self.x_max,
                self.watchdog_ms, P.MAX_DELAY, 16,
            ))
        elif isinstance(frame, P.Configure):
            ok = (frame.period_us == self.period_us and 1 <= frame.watchdog_ms <= 60000 and 1 <= frame.delay <= P.MAX_DELAY
                  and frame.x_min < frame.x_max and 0 < frame.v_max_mv <= 10000)
            if ok:
                self.watchdog_ms, self.delay = frame.watchdog_ms, frame.delay
                self.x_min, self.x_max, self.v_max_mv = frame.x_min, frame.x_max, frame.v_max_mv
                self.say(f"configured: period {self.period_us} us, delay N = {self.delay}, watchdog {self.watchdog_ms} ms, "
                         f"track {self.x_min / self.counts_per_m:+.3f} .. {self.x_max / self.counts_per_m:+.3f} m")
            self.send(P.Ack(self._next_seq(), P.Configure.TYPE, P.ACK_OK if ok else P.ACK_RANGE))
        elif isinstance(frame, P.Zero):
            x, _, alpha, _, _ = self.plant.state()
            if frame.which & P.ZERO_CART:
                self.zero_cart = self._cart_raw(x)
            if frame.which & P.ZERO_PENDULUM:
                # (the seesaw held level by the hand reads level; the held pendulum is zeroed hanging, as before)
                self.zero_pend = self._pend_raw(self.kind["hold"] if self.held and self.o.plant == "seesaw" else alpha)
            self.send(P.Ack(self._next_seq(), P.Zero.TYPE, P.ACK_OK))
        elif isinstance(frame, P.Stream):
            if frame.on and not self.streaming:
                self.streaming, self.tick, self.late = True, 0, 0
                self.ring = [None] * RING
                self.sample_seqs.clear()
                self.sent_at.clear()
                self.last_command_time = now
                self.say("streaming samples")
            elif not frame.on and self.streaming:
                self.streaming = False
                self._disable("streaming stopped by the host")
            self.send(P.Ack(self._next_seq(), P.Stream.TYPE, P.ACK_OK))
        elif isinstance(frame, P.Command):
            self.ring[frame.answers % RING] = frame
            self.last_command_time = now

    def _cart_raw(self, x: float) -> int:
        return int(math.floor(x * self.counts_per_m + 0.5))

    def _pend_raw(self, alpha: float) -> int:
        # The pendulum's encoder reads the angle from hanging (theta = alpha - pi), counter-clockwise positive;
        # the seesaw's reads the tilt from level.
        return int(math.floor((alpha - self.kind["encoder_zero"]) * self.counts_per_rad + 0.5))

    def _disable(self, why: str) -> None:
        if self.enabled or self.voltage != 0.0:
            self.say(f"motor off: {why}")
        self.enabled = False
        self.voltage = 0.0

    def _check_watchdog(self, now: float) -> None:
        """No valid command for the watchdog time: 0 V, disabled, latched until a clear."""
        if self.last_command_time is not None and now - self.last_command_time > self.watchdog_ms / 1000.0 and not self.wd_tripped:
            self.wd_tripped = True
            self._disable(f"watchdog tripped: no valid command for {self.watchdog_ms} ms -> 0 V")

    def _tick(self, now: float) -> None:
        """One period of the firmware: choose and apply the voltage, send the sample."""
        x, _, alpha, _, _ = self.plant.state()
        if self.held:
            alpha = self.kind["hold"]
        cart = self._encoder("cart", self._cart_raw(x) - self.zero_cart, now)
        pend = self._encoder("pendulum", self._pend_raw(alpha) - self.zero_pend, now)
        status_late = 0
        due: P.Command | None = None
        if len(self.sample_seqs) >= self.delay:
            want = self.sample_seqs[-self.delay]
            cmd = self.ring[want % RING]
            if (cmd is None or cmd.answers != want) and self._clock is not None:
                # This process, not a rig's timer, may have sent that sample late (an OS scheduling
                # delay): the host gets its full N periods from when the sample really went out. What
                # arrived by then is read even if this process itself was not running at the deadline.
                deadline = self.sent_at[-self.delay] + self.delay * self.o.period
                while True:
                    at = self._clock()
                    for frame in self._receive(at):
                        self._handle(frame, at)
                    cmd = self.ring[want % RING]
                    if (cmd is not None and cmd.answers == want) or at >= deadline:
                        break
                    self._wait_for_bytes(deadline)  # blocking: a spinning real-time process starves the pty's worker
            if cmd is not None and cmd.answers == want:
                due = cmd
            else:
                self.late = (self.late + 1) & 0xFFFF
                status_late = P.ST_LATE
        if due is not None:
            self.applied = due.answers
            if due.flags & P.CLEAR and (self.wd_tripped or self.limit_hit):
                self.wd_tripped = self.limit_hit = False
                self.say("watchdog and limit flags cleared by the host")
            if due.flags & P.ENABLE and not (self.wd_tripped or self.limit_hit or self.fault):
                if not self.enabled:
                    self.say("motor enabled")
                self.enabled = True
                limit = self.v_max_mv / 1000.0
                self.voltage = max(-limit, min(limit, due.voltage_mv / 1000.0))
            elif self.enabled:
                self._disable("the host disabled the amplifier")
        # The second, independent safety layer: watchdog and track limits.
        self._check_watchdog(now)
        if not self.limit_hit and not (self.x_min <= cart <= self.x_max):
            self.limit_hit = True
            self._disable(f"track limit hit at x = {cart / self.counts_per_m:+.3f} m -> 0 V")
        if self.wd_tripped or self.limit_hit or self.fault:
            self.enabled, self.voltage = False, 0.0
        # The pendulum's hand lets go when the motor acts; the seesaw's at the start (level, with the cart centred,
        # the controller may well command 0 V).
        if self.enabled and self.held and (self.voltage != 0.0 or self.o.plant == "seesaw"):
            self._release()
        status = ((P.ST_ENABLED if self.enabled else 0) | (P.ST_WATCHDOG if self.wd_tripped else 0)
                  | (P.ST_LIMIT if self.limit_hit else 0) | (P.ST_FAULT if self.fault else 0) | status_late)
        seq = self._next_seq()
        self.sample_seqs.append(seq)
        self.sent_at.append(self._clock() if self._clock is not None else now)
        self.send(P.Sample(seq, self.tick & 0xFFFFFFFF, cart & 0xFFFF, pend & 0xFFFF, int(round(self.voltage * 1000)),
                           status, self.late, self.applied))
        self.tick += 1

    def _encoder(self, name: str, count: int, now: float) -> int:
        """The count an encoder gives: the true one, or a dead or frozen encoder's (from its fault time on)."""
        fault = self.o.encoder_faults.get(name)
        since = None if self.connected_at is None else now - self.connected_at
        if fault is None or since is None or since < fault[1]:
            self._last_counts[name] = count
            return count
        if name not in self._failed:
            held = self._last_counts.get(name, count)
            # A dead encoder's lines drop low: the decoder sees one last edge, to the phase 0 below its count.
            self._failed[name] = held - held % 4 if fault[0] == "dead" else held
            self.say(f"{name} encoder {fault[0]}: its count stays at {self._failed[name]}")
        return self._failed[name]

    # ------------------------------------------------------------------ the person
    def _raise(self) -> None:
        self.held = True
        self.raised = True
        if self.o.plant == "seesaw":
            # (the cart slid down the tilted track meanwhile: the person centres it, as Quanser's lab asks before a start)
            self.plant.restart(self.plant.t, (0.0, 0.0, 0.0, 0.0))
            self.say("seesaw lifted level off its tilt stop by hand, cart centred; held until the motor is enabled")
        else:
            self.say(f"pendulum raised by hand to {math.degrees(HOLD_ANGLE):.1f} deg from upright; held until the motor is enabled")

    def _hold_level(self) -> None:
        """The hand keeps the seesaw level and the cart still (motor off): the plant restarts there."""
        x, _, _, _, _ = self.plant.state()
        self.plant.restart(self.plant.t, (x, 0.0, 0.0, 0.0))

    def _release(self) -> None:
        """The controller has it: the hand lets go (the plant restarts from the held state)."""
        x, xdot, _, _, _ = self.plant.state()
        changes: dict[str, float] = {}
        what, poke = self.kind["what"], self.kind["poke"]
        if self.o.poke is not None:
            mag, dur, start = self.o.poke
            changes = {f"{poke}_magnitude": mag, f"{poke}_duration": dur, f"{poke}_start": self.plant.t + start}
            self.say(f"hand released, the controller has the {what}; {poke} {mag:g} rad/s^2 for {dur:g} s at t = {self.plant.t + start:.3f} s")
        else:
            self.say(f"hand released, the controller has the {what}")
        self.plant.restart(self.plant.t, (x, xdot, self.kind["hold"], 0.0), **changes)
        self.held = False

    # ------------------------------------------------------------------ the loop
    def run(self, duration: float | None = None) -> str:
        """Run in real time until stopped (or for ``duration`` s); returns why it ended."""
        assert self._read is not None, "open_pty() or use_socket() first"
        with no_garbage_collection():  # none in the real-time loop (see pendulab.hil.realtime)
            return self._run(duration)

    def _run(self, duration: float | None) -> str:
        period = self.o.period
        stalled_until = -1.0
        stalled_said = False
        t0 = time.perf_counter()
        self._clock = lambda: time.perf_counter() - t0
        next_tick = t0
        k = 0
        lag = 0.0
        while not self._stop:
            # Wait for the tick, reading the host's bytes as they come (so that the link's latency counts
            # from when they were written). Blocking to the tick, never spinning: the bytes this process
            # waits for are delivered by kernel workers that a spinning real-time process keeps off its
            # core (a sleep wakes some 50 us late, which the host never sees: its N periods count from
            # when each sample really went out).
            while True:
                now = time.perf_counter()
                left = next_tick - now
                if left <= 0:
                    break
                if self._fileno is not None and now - t0 >= stalled_until:
                    if select.select([self._fileno], [], [], left)[0]:
                        try:
                            self._pull(time.perf_counter() - t0)
                        except ConnectionError:
                            # Seen again (and handled) at the tick; a closed socket stays readable: no busy wait.
                            time.sleep(max(0.0, next_tick - time.perf_counter()))
                else:
                    time.sleep(left)
            now = time.perf_counter() - t0
            # How late this tick runs. A rig's timer never stops, but this process may not run (the OS gives
            # the core to others, here or inside the last tick): when the lateness grows, the host had no sample
            # to answer for that long, so the growth does not count against the host in the watchdog (a 90 ms
            # stall of this emulator on a loaded host tripped it). Only the growth: a lateness that persists was
            # credited once (crediting it at every tick kept a silent host from ever tripping the watchdog).
            late_now = now - (next_tick - t0)
            if late_now > lag and self.last_command_time is not None:
                self.last_command_time += late_now - lag
            lag = max(late_now, 0.0)
            if late_now > 0.05:  # suspended (debugger, overload): do not race to catch up
                next_tick = t0 + now
                lag = 0.0
            if duration is not None and now >= duration:
                return "duration"
            since = None if self.connected_at is None else now - self.connected_at
            if since is not None:
                if self.o.close_after is not None and since >= self.o.close_after:
                    self.say("closing the port (--close-after)")
                    return "closed"
                if self.o.restart_after is not None and since >= self.o.restart_after:
                    self.o.restart_after = None
                    self._boot()
                    self.connected_at = now
                    self.say(f"restart: firmware reset, new boot id {self.boot_id:#010x}, motor off")
                if self.o.stall_after is not None and since >= self.o.stall_after:
                    self.o.stall_after = None
                    stalled_until = now + self.o.stall_for
                    self.say(f"link stalled for {self.o.stall_for:g} s (--stall-after)")
                    stalled_said = True
                if self.o.fault_after is not None and since >= self.o.fault_after and not self.fault:
                    self.fault = True
                    self._disable("fault (amplifier fault input) -> 0 V until reset")
                    self.say("fault")
                if self.o.raise_after is not None and not self.raised and since >= self.o.raise_after:
                    self._raise()
            if now < stalled_until:
                pass  # nothing crosses the link; the rig's own clock and watchdog go on
            else:
                if stalled_said:
                    self.say("link back")
                    stalled_said = False
                try:
                    frames = self._receive(now)
                except ConnectionError:
                    self.say("host disconnected")
                    return "disconnected"
                for frame in frames:
                    self._handle(frame, now)
            if self.streaming:
                if now < stalled_until:
                    # Samples are taken but lost on the stalled link; the watchdog still runs.
                    self._check_watchdog(now)
                    self.tick += 1
                else:
                    self._tick(now)
            if self.held and self.o.plant == "seesaw" and k % HOLD_EVERY == 0:
                self._hold_level()
            self.plant.step(self.voltage)
            k += 1
            next_tick += period
        return "stopped"
