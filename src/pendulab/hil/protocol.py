"""The rig protocol, version 1 (``docs/protocol.md``): COBS frames with a sequence number and a CRC-16.

Frames are small frozen data classes; :func:`encode` turns one into the bytes on the wire and
:class:`FrameReader` turns a byte stream back into frames, counting what it had to reject.

Examples
--------
>>> wire = encode(Command(seq=7, answers=41, voltage_mv=-2500, flags=ENABLE))
>>> reader = FrameReader()
>>> reader.feed(b"\\x13garbage\\x00" + wire)
[Command(seq=7, answers=41, voltage_mv=-2500, flags=1)]
>>> reader.errors
1
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, fields
from typing import ClassVar, Union

PROTOCOL_VERSION = 1
#: 1 Mbaud: exact from a 16 MHz AVR clock (921600 is 8 % off there), and >= 921600 as the lab needs.
DEFAULT_BAUD = 1_000_000
#: Largest transport delay N (periods) a CONFIGURE may ask for (docs/protocol.md, section 3).
MAX_DELAY = 8
#: The longest delay the host accepts when it measures the link, unless told otherwise (a USB bridge needs 2-3).
DEFAULT_MAX_DELAY = 4
#: Longest decoded frame a reader stores; anything longer is rejected unread.
MAX_FRAME = 64

# COMMAND flags
ENABLE = 0x01
CLEAR = 0x02
# SAMPLE status bits
ST_ENABLED = 0x01
ST_WATCHDOG = 0x02
ST_LIMIT = 0x04
ST_FAULT = 0x08
ST_LATE = 0x10
# ZERO bits
ZERO_CART = 0x01
ZERO_PENDULUM = 0x02
# ACK results
ACK_OK, ACK_RANGE, ACK_NOT_NOW = 0, 1, 2


# ---------------------------------------------------------------- CRC-16/CCITT-FALSE
def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE: polynomial 0x1021, init 0xFFFF, no reflection, no final XOR.

    >>> hex(crc16(b"123456789"))
    '0x29b1'
    """
    crc = 0xFFFF
    table = _CRC_TABLE
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ b]
    return crc


# ---------------------------------------------------------------- COBS
def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: the same bytes with no zero (the 0x00 delimiter is not added)."""
    out = bytearray([0])
    code_at, code = 0, 1
    for b in data:
        if b == 0:
            out[code_at] = code
            code_at, code = len(out), 1
            out.append(0)
        else:
            out.append(b)
            code += 1
            if code == 0xFF:
                out[code_at] = code
                code_at, code = len(out), 1
                out.append(0)
    out[code_at] = code
    return bytes(out)


def cobs_decode(data: bytes) -> bytes | None:
    """The inverse of :func:`cobs_encode`; None for bytes no encoder could have produced."""
    out = bytearray()
    i, n = 0, len(data)
    while i < n:
        code = data[i]
        if code == 0 or i + code > n:
            return None
        block = data[i + 1 : i + code]
        if 0 in block:
            return None
        out += block
        i += code
        if code < 0xFF and i < n:
            out.append(0)
    return bytes(out)


# ---------------------------------------------------------------- frames
@dataclass(frozen=True)
class Frame:
    """Base of every frame: ``seq`` is the sender's sequence number (mod 65536)."""

    TYPE: ClassVar[int] = 0
    FORMAT: ClassVar[str] = ""
    seq: int

    def payload(self) -> bytes:
        return struct.pack("<" + self.FORMAT, *(getattr(self, f.name) for f in fields(self)[1:]))


@dataclass(frozen=True)
class Identify(Frame):
    TYPE: ClassVar[int] = 0x01
    FORMAT: ClassVar[str] = "B"
    protocol: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class Configure(Frame):
    TYPE: ClassVar[int] = 0x02
    FORMAT: ClassVar[str] = "IHBiiH"
    period_us: int = 1000
    watchdog_ms: int = 20
    delay: int = 1
    x_min: int = -2**31
    x_max: int = 2**31 - 1
    v_max_mv: int = 10000


@dataclass(frozen=True)
class Command(Frame):
    TYPE: ClassVar[int] = 0x03
    FORMAT: ClassVar[str] = "HhB"
    answers: int = 0
    voltage_mv: int = 0
    flags: int = 0


@dataclass(frozen=True)
class Zero(Frame):
    TYPE: ClassVar[int] = 0x04
    FORMAT: ClassVar[str] = "B"
    which: int = ZERO_CART | ZERO_PENDULUM


@dataclass(frozen=True)
class Stream(Frame):
    TYPE: ClassVar[int] = 0x05
    FORMAT: ClassVar[str] = "B"
    on: int = 1


@dataclass(frozen=True)
class Identity(Frame):
    TYPE: ClassVar[int] = 0x81
    FORMAT: ClassVar[str] = "BBBBIIffHiiHBB"
    protocol: int = PROTOCOL_VERSION
    fw_major: int = 0
    fw_minor: int = 0
    fw_patch: int = 0
    boot_id: int = 0
    period_us: int = 1000
    cart_counts_per_m: float = 1 / 22.75e-6
    pend_counts_per_rad: float = 4096 / 6.283185307179586
    v_max_mv: int = 10000
    x_min: int = -2**31
    x_max: int = 2**31 - 1
    watchdog_ms: int = 20
    max_delay: int = 8
    counter_bits: int = 16


@dataclass(frozen=True)
class Sample(Frame):
    TYPE: ClassVar[int] = 0x82
    FORMAT: ClassVar[str] = "IHHhBHH"
    tick: int = 0
    cart: int = 0
    pend: int = 0
    voltage_mv: int = 0
    status: int = 0
    late: int = 0
    applied: int = 0


@dataclass(frozen=True)
class Ack(Frame):
    TYPE: ClassVar[int] = 0x83
    FORMAT: ClassVar[str] = "BB"
    acked: int = 0
    result: int = ACK_OK


AnyFrame = Union[Identify, Configure, Command, Zero, Stream, Identity, Sample, Ack]
FRAME_TYPES: dict[int, type[Frame]] = {cls.TYPE: cls for cls in (Identify, Configure, Command, Zero, Stream, Identity, Sample, Ack)}
_SIZES = {t: struct.calcsize("<" + cls.FORMAT) for t, cls in FRAME_TYPES.items()}
_HEADER = struct.Struct("<BH")


def encode(frame: Frame) -> bytes:
    """The frame's bytes on the wire: ``COBS(type seq payload crc) 0x00``."""
    body = _HEADER.pack(frame.TYPE, frame.seq & 0xFFFF) + frame.payload()
    return cobs_encode(body + struct.pack("<H", crc16(body))) + b"\x00"


def decode(packet: bytes) -> Frame | None:
    """One frame from the bytes between two delimiters; None if it is not a valid frame."""
    raw = cobs_decode(packet)
    if raw is None or len(raw) < 5:
        return None
    body, (crc,) = raw[:-2], struct.unpack("<H", raw[-2:])
    if crc16(body) != crc:
        return None
    kind, seq = _HEADER.unpack_from(body)
    cls = FRAME_TYPES.get(kind)
    if cls is None or len(body) - 3 != _SIZES[kind]:
        return None
    return cls(seq, *struct.unpack_from("<" + cls.FORMAT, body, 3))


def wire_size(cls: type[Frame]) -> int:
    """Bytes one frame of this type takes on the wire (COBS overhead and delimiter included)."""
    n = 3 + _SIZES[cls.TYPE] + 2
    return n + 1 + n // 254 + 1


class FrameReader:
    """Splits a byte stream into frames; rejected packets are counted, never returned.

    Attributes
    ----------
    errors : int
        Packets rejected (bad COBS, bad CRC, unknown type, wrong length, too long).
    lost : int
        Frames missing according to the peer's sequence numbers.
    frames : int
        Valid frames returned.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self._overflow = False
        self._last_seq: int | None = None
        self.errors = 0
        self.lost = 0
        self.frames = 0

    def feed(self, data: bytes) -> list[Frame]:
        """Frames completed by ``data`` (in order)."""
        out: list[Frame] = []
        start = 0
        while True:
            end = data.find(0, start)
            if end < 0:
                chunk = data[start:]
                if len(self._buffer) + len(chunk) > 2 * MAX_FRAME:
                    self._overflow = True
                    self._buffer.clear()
                else:
                    self._buffer += chunk
                return out
            packet = bytes(self._buffer) + data[start:end]
            self._buffer.clear()
            start = end + 1
            if self._overflow:
                self._overflow = False
                self.errors += 1
                continue
            if not packet:
                continue  # two delimiters in a row: an idle line, not an error
            frame = decode(packet) if len(packet) <= MAX_FRAME + 2 else None
            if frame is None:
                self.errors += 1
                continue
            if self._last_seq is not None:
                gap = (frame.seq - self._last_seq) & 0xFFFF
                if 1 < gap < 0x8000:
                    self.lost += gap - 1
            self._last_seq = frame.seq
            self.frames += 1
            out.append(frame)


def unwrap16(previous: int, raw: int) -> int:
    """The full count from a 16-bit counter reading, given the previous full count.

    >>> unwrap16(32767, 0x8000), unwrap16(0, 0xFFFF), unwrap16(70000, 70000 & 0xFFFF)
    (32768, -1, 70000)
    """
    delta = (raw - previous) & 0xFFFF
    if delta >= 0x8000:
        delta -= 0x10000
    return previous + delta
