"""The host's end of the serial link: open, identify, configure, stream, answer (protocol v1).

Examples
--------
>>> # skipped: needs a rig (or 'pendulab rig-emulator') on the serial port
>>> with RigLink.open("/dev/ttyACM0") as link:                       # doctest: +SKIP
...     identity = link.identify()
...     link.configure(delay=1)
...     link.stream(True)
...     sample, received_at = link.next_sample(timeout=0.1)
...     link.command(sample.seq, 0.0, enable=False)
"""

from __future__ import annotations

import os
import select
import time
from collections import deque
from typing import Any

from pendulab.errors import UserError
from pendulab.hil import protocol as P

#: Tries of a set-up request (CONFIGURE, ZERO, STREAM on) whose acknowledgement does not come.
REQUEST_TRIES = 3

#: A write fails only when the port takes no byte for this long (s). The rig reads a frame every period, so a
#: full output buffer means its other end is briefly not reading (a pseudo-terminal's peer or the kernel's
#: worker not scheduled on a loaded host); the rig's watchdog, not this, judges whether answers came in time.
WRITE_STALL = 2.0


class LinkLost(Exception):
    """The port failed or went silent; the message says how."""


class RigRestarted(Exception):
    """The rig reset during a session (new boot id or its tick went back)."""


def available_ports() -> str:
    """``"; serial ports here: COM3 (USB Serial Device), ..."`` for an error message, or ``""`` if none.

    On a Windows lab PC the rig's COM number changes with the USB socket it is plugged into, so a TA
    who gave the wrong one sees the right one in the same line.
    """
    try:
        from serial.tools.list_ports import comports

        ports = sorted(comports(), key=lambda p: (len(p.device), p.device))  # COM3 before COM10
    except Exception:  # noqa: BLE001 - listing is a courtesy; the error itself is what matters
        return ""
    names = [f"{p.device} ({p.description})" if p.description and p.description != "n/a" else p.device for p in ports]
    return f"; serial ports here: {', '.join(names)}" if names else "; no serial port found here (is the rig plugged in?)"


class RigLink:
    """A rig on a pyserial port (a device, ``socket://HOST:PORT``, ``loop://``).

    Attributes
    ----------
    reader : FrameReader
        Counts rejected frames (``errors``) and frames lost by sequence number (``lost``).
    """

    def __init__(self, serial_port: Any, name: str) -> None:
        self.port = serial_port
        self.name = name
        self.reader = P.FrameReader()
        self.seq = 0
        self.identity: P.Identity | None = None
        self._frames: deque[tuple[P.Frame, float]] = deque()
        self.bytes_in = 0
        self._fd = _writable_fd(serial_port)

    @classmethod
    def open(cls, port: str, baud: int = P.DEFAULT_BAUD) -> "RigLink":
        import serial

        try:
            handle = serial.serial_for_url(port, baudrate=baud, timeout=0.05, write_timeout=WRITE_STALL, do_not_open=True)
            if hasattr(handle, "exclusive") and not port.startswith(("socket://", "loop://", "rfc2217://")):
                try:
                    handle.exclusive = True  # two programs on one rig would fight over the motor
                except (ValueError, NotImplementedError):
                    pass
            handle.open()
        except (serial.SerialException, ValueError, OSError) as exc:
            text = str(exc).split("\n")[0]
            raise UserError(
                f"cannot open port {port!r}: {text}; give the rig's port (COM3 on Windows, /dev/ttyACM0 or /dev/ttyUSB0 on "
                f"Linux, socket://HOST:PORT for a rig on another machine){available_ports()}"
            ) from None
        return cls(handle, port)

    def close(self) -> None:
        try:
            self.port.close()
        except Exception:  # noqa: BLE001 - closing a dead port must not hide why it died
            pass

    def __enter__(self) -> "RigLink":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ bytes and frames
    def send(self, frame_type: type[P.Frame], **fields: Any) -> None:
        frame = frame_type(self.seq, **fields)
        self.seq = (self.seq + 1) & 0xFFFF
        try:
            if self._fd is None:
                self.port.write(P.encode(frame))  # pyserial's own write (Windows: it waits for the bytes to be taken)
            else:
                _write_all(self._fd, P.encode(frame))
        except Exception as exc:  # noqa: BLE001 - pyserial raises SerialException, OSError, ...
            raise LinkLost(f"link lost: writing to {self.name} failed ({exc})") from None

    def _pump(self, timeout: float) -> None:
        """Read what has arrived (waiting up to ``timeout`` for the first byte) into the frame queue."""
        port = self.port
        try:
            port.timeout = timeout
            data = port.read(max(1, port.in_waiting))
        except Exception as exc:  # noqa: BLE001
            raise LinkLost(f"link lost: reading from {self.name} failed ({str(exc).splitlines()[0]})") from None
        if data:
            now = time.perf_counter()
            self.bytes_in += len(data)
            for frame in self.reader.feed(data):
                self._frames.append((frame, now))

    def next_frame(self, timeout: float) -> tuple[P.Frame, float] | None:
        """The next valid frame and the time (perf_counter) its last byte was read, or None after ``timeout``.

        What has already arrived is always read before giving up: a host that was not scheduled past its
        deadline (a loaded machine) must not take the rig's waiting samples for silence.
        """
        deadline = time.perf_counter() + timeout
        while not self._frames:
            left = deadline - time.perf_counter()
            self._pump(max(left, 0.0))
            if left <= 0:
                break
        return self._frames.popleft() if self._frames else None

    def next_sample(self, timeout: float) -> tuple[P.Sample, float] | None:
        """The next SAMPLE (other frames in between are dropped), or None after ``timeout``."""
        return self.expect(P.Sample, timeout)  # type: ignore[return-value]

    def expect(self, kind: type[P.Frame], timeout: float) -> tuple[P.Frame, float] | None:
        """The next frame of type ``kind`` (others in between are dropped), or None after ``timeout``."""
        deadline = time.perf_counter() + timeout
        while True:
            item = self.next_frame(max(0.0, deadline - time.perf_counter()))
            if item is None or isinstance(item[0], kind):
                return item

    # ------------------------------------------------------------------ the session
    def identify(self, timeout: float = 1.0) -> P.Identity:
        """Ask who is there; a clear :class:`UserError` if it is not a rig of our protocol."""
        try:
            self.port.reset_input_buffer()
        except Exception:  # noqa: BLE001
            pass
        before = self.bytes_in
        item = None
        for _ in range(REQUEST_TRIES):
            self.send(P.Identify, protocol=P.PROTOCOL_VERSION)
            item = self.expect(P.Identity, timeout)
            if item is not None or self.bytes_in == before:
                break  # an answer, or silence: asking again would not change it
            # Bytes came but no valid IDENTITY: on a noisy link the answer may have been corrupted; ask again.
        if item is None:
            if self.bytes_in > before:
                raise UserError(
                    f"{self.name} is not a pendulab rig: it sent {self.bytes_in - before} bytes but no valid frame within "
                    f"{timeout:g} s; check the port and that the rig runs the pendulab firmware at {self.port.baudrate} baud"
                )
            raise UserError(
                f"no reply from {self.name} within {timeout:g} s; check that the rig is connected and powered, runs the "
                f"pendulab firmware, and that this is its port"
            )
        identity: P.Identity = item[0]  # type: ignore[assignment]
        if identity.protocol != P.PROTOCOL_VERSION:
            raise UserError(
                f"the rig at {self.name} speaks protocol version {identity.protocol}, this pendulab speaks version "
                f"{P.PROTOCOL_VERSION}; flash the firmware that matches this pendulab (or install the pendulab that matches the rig)"
            )
        self.identity = identity
        return identity

    def round_trips(self, count: int = 20, timeout: float = 0.2) -> list[float]:
        """Round trips (s) of IDENTIFY -> IDENTITY, for the record (the delay is chosen on samples)."""
        out = []
        for _ in range(count):
            start = time.perf_counter()
            self.send(P.Identify, protocol=P.PROTOCOL_VERSION)
            item = self.expect(P.Identity, timeout)
            if item is not None:
                out.append(item[1] - start)
        return out

    def _acked(self, kind: type[P.Frame], timeout: float = 0.5) -> P.Ack:
        deadline = time.perf_counter() + timeout
        while True:
            item = self.expect(P.Ack, max(0.0, deadline - time.perf_counter()))
            if item is None:
                raise LinkLost(f"link lost: the rig at {self.name} did not acknowledge {kind.__name__.upper()} within {timeout:g} s")
            if item[0].acked == kind.TYPE:  # type: ignore[attr-defined]
                return item[0]  # type: ignore[return-value]

    def configure(self, *, delay: int, watchdog_ms: int = 20, x_limit: float | None = None, v_max: float = 10.0) -> None:
        identity = self.identity
        assert identity is not None, "identify() first"
        if x_limit is None:
            x_min, x_max = identity.x_min, identity.x_max
        else:
            x_max = int(x_limit * identity.cart_counts_per_m)
            x_min = -x_max
        ack = self._request(P.Configure, period_us=identity.period_us, watchdog_ms=watchdog_ms, delay=delay,
                            x_min=x_min, x_max=x_max, v_max_mv=int(round(v_max * 1000)))
        if ack.result != P.ACK_OK:
            raise UserError(f"the rig refused the configuration (delay {delay}, watchdog {watchdog_ms} ms, track ±{x_limit} m): result {ack.result}")
        self.delay = delay

    def _request(self, kind: type[P.Frame], tries: int = REQUEST_TRIES, **fields: Any) -> P.Ack:
        """Send a set-up request and wait for its acknowledgement, again when either is lost on a noisy link.

        CONFIGURE, ZERO and STREAM on are idempotent on the rig: a repeated one changes nothing.
        """
        for attempt in range(tries):
            self.send(kind, **fields)
            try:
                return self._acked(kind)
            except LinkLost:
                if attempt == tries - 1:
                    raise LinkLost(f"link lost: the rig at {self.name} did not acknowledge {kind.__name__.upper()} "
                                   f"in {tries} tries of 0.5 s") from None
        raise AssertionError("unreachable")

    def zero(self, which: int = P.ZERO_CART | P.ZERO_PENDULUM) -> None:
        self._request(P.Zero, which=which)

    def stream(self, on: bool) -> None:
        if on:
            self._request(P.Stream, on=1)
        else:
            self.send(P.Stream, on=0)
            try:  # on the way out: the ack is welcome, not needed
                self._acked(P.Stream, timeout=0.1)
            except LinkLost:
                pass
            # Samples sent before the rig stopped belong to the stream that ended, not to the next.
            self._frames.clear()

    def command(self, answers: int, voltage: float, *, enable: bool, clear: bool = False) -> None:
        mv = int(round(max(-32.0, min(32.0, voltage)) * 1000))
        self.send(P.Command, answers=answers, voltage_mv=mv, flags=(P.ENABLE if enable else 0) | (P.CLEAR if clear else 0))

    def silence_cause(self, silent_ms: float, timeout: float = 0.3, tries: int = 3) -> Exception:
        """Why the samples stopped: a restarted rig answers IDENTIFY with a new boot id; a dead link does not answer.

        IDENTIFY is sent up to ``tries`` times, ``timeout`` s each: on a noisy link one corrupted request or answer
        made a restarted rig read as a lost link. Returns (does not raise) :class:`RigRestarted` or
        :class:`LinkLost`, whose message says which.
        """
        old = self.identity
        item = None
        try:
            for _ in range(tries):
                self.send(P.Identify, protocol=P.PROTOCOL_VERSION)
                item = self.expect(P.Identity, timeout)
                if item is not None:
                    break
        except LinkLost as exc:
            return exc
        if item is None:
            return LinkLost(f"link lost: no data from the rig for {silent_ms + tries * timeout * 1e3:.0f} ms")
        identity: P.Identity = item[0]  # type: ignore[assignment]
        if old is not None and identity.boot_id != old.boot_id:
            return RigRestarted(f"the rig restarted (boot id {old.boot_id:#010x} -> {identity.boot_id:#010x})")
        return LinkLost(f"link lost: no sample for {silent_ms:.0f} ms, then the rig (same boot id) answered again: the link stalled "
                        "or the rig stopped streaming")

    def motor_off(self, answers: int = 0) -> None:
        """Zero volts, amplifier disabled, stream stopped; never raises (used on every way out)."""
        for action in (lambda: self.command(answers, 0.0, enable=False), lambda: self.stream(False)):
            try:
                action()
            except (LinkLost, Exception):  # noqa: BLE001
                pass


def _writable_fd(port: Any) -> int | None:
    """The port's non-blocking file descriptor where the host writes to it itself (POSIX), else None.

    pyserial's POSIX write with a write timeout fails a write whose bytes the kernel has all taken when the
    buffer is full just after it (it then waits for room), and gives up after the timeout even while the
    other end is only briefly not reading: measured on a pseudo-terminal, "Write timeout" raised for a frame
    that its peer then read. Windows' write waits for the bytes to be taken, as wanted.
    """
    if os.name != "posix":
        return None
    try:
        fd = port.fileno()
        return fd if isinstance(fd, int) and not os.get_blocking(fd) else None
    except Exception:  # noqa: BLE001 - a port without a file descriptor (loop://): pyserial writes
        return None


def _write_all(fd: int, data: bytes) -> None:
    """Write every byte; OSError when the port took no byte for :data:`WRITE_STALL` s."""
    view = memoryview(data)
    last_progress = time.perf_counter()
    while view:
        try:
            n = os.write(fd, view)
        except BlockingIOError:
            n = 0
        if n:
            view = view[n:]
            last_progress = time.perf_counter()
            continue
        left = last_progress + WRITE_STALL - time.perf_counter()
        if left <= 0:
            raise OSError(f"the port took no byte for {WRITE_STALL:g} s: the rig stopped reading")
        select.select([], [fd], [], min(left, 0.05))


class Encoders:
    """Unwraps the 16-bit counters of SAMPLE frames into positions in SI units."""

    def __init__(self, identity: P.Identity) -> None:
        self.m_per_count = 1.0 / identity.cart_counts_per_m
        self.rad_per_count = 1.0 / identity.pend_counts_per_rad
        self._cart: int | None = None
        self._pend: int | None = None

    def update(self, sample: P.Sample) -> tuple[float, float]:
        """``(x, theta)``: cart position (m) and pendulum angle from hanging (rad)."""
        if self._cart is None or self._pend is None:
            self._cart = sample.cart - 0x10000 if sample.cart >= 0x8000 else sample.cart
            self._pend = sample.pend - 0x10000 if sample.pend >= 0x8000 else sample.pend
        else:
            self._cart = P.unwrap16(self._cart, sample.cart)
            self._pend = P.unwrap16(self._pend, sample.pend)
        return self._cart * self.m_per_count, self._pend * self.rad_per_count
