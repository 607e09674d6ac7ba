"""Protocol v1 (docs/protocol.md): frames round-trip, corruption is rejected, the reader resynchronizes."""

from __future__ import annotations

import random
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pendulab.hil import protocol as P

U16 = st.integers(0, 0xFFFF)
U32 = st.integers(0, 0xFFFFFFFF)
I16 = st.integers(-32768, 32767)
I32 = st.integers(-2**31, 2**31 - 1)
U8 = st.integers(0, 255)
F32 = st.floats(width=32, allow_nan=False, allow_infinity=False)

FRAMES = st.one_of(
    st.builds(P.Identify, U16, U8),
    st.builds(P.Configure, U16, U32, U16, U8, I32, I32, U16),
    st.builds(P.Command, U16, U16, I16, U8),
    st.builds(P.Zero, U16, U8),
    st.builds(P.Stream, U16, U8),
    st.builds(P.Identity, U16, U8, U8, U8, U8, U32, U32, F32, F32, U16, I32, I32, U16, U8, U8),
    st.builds(P.Sample, U16, U32, U16, U16, I16, U8, U16, U16),
    st.builds(P.Ack, U16, U8, U8),
)

#: One frame of each type with typical values (every byte value class: zeros, 0xFF, small numbers).
TYPICAL = [
    P.Identify(0),
    P.Configure(1, 1000, 20, 1, -19340, 19340, 10000),
    P.Command(2, 4711, -2500, P.ENABLE),
    P.Command(0xFFFF, 0, 0, 0),
    P.Zero(3),
    P.Stream(4, 1),
    P.Identity(5, 1, 1, 0, 0, 0xDEADBEEF, 1000, 43956.0, 651.9, 10000, -19780, 19780, 20, 8, 16),
    P.Sample(6, 123456, 0xFFFF, 0x0000, -10000, P.ST_ENABLED | P.ST_LATE, 3, 5),
    P.Ack(7, P.Configure.TYPE, P.ACK_OK),
]


def test_crc_check_value_and_polynomial():
    # CRC-16/CCITT-FALSE's published check value, and a bitwise reference implementation.
    assert P.crc16(b"123456789") == 0x29B1

    def bitwise(data: bytes) -> int:
        crc = 0xFFFF
        for b in data:
            crc ^= b << 8
            for _ in range(8):
                crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
        return crc

    rng = random.Random(1)
    for n in (0, 1, 7, 64):
        data = bytes(rng.randrange(256) for _ in range(n))
        assert P.crc16(data) == bitwise(data)


@settings(deadline=None)
@given(st.binary(max_size=600))
def test_cobs_round_trip_and_no_zero(data):
    encoded = P.cobs_encode(data)
    assert 0 not in encoded
    assert len(encoded) <= len(data) + 1 + len(data) // 254 + 1
    assert P.cobs_decode(encoded) == data


@settings(deadline=None)
@given(FRAMES)
def test_every_frame_round_trips(frame):
    wire = P.encode(frame)
    assert wire.endswith(b"\x00") and 0 not in wire[:-1]
    assert len(wire) == P.wire_size(type(frame))
    decoded = P.FrameReader().feed(wire)
    assert len(decoded) == 1
    got = decoded[0]
    assert type(got) is type(frame)
    for name, value in vars(frame).items():
        expected = struct.unpack("<f", struct.pack("<f", value))[0] if isinstance(value, float) else value
        assert getattr(got, name) == expected


def _rejected(wire: bytes) -> bool:
    reader = P.FrameReader()
    frames = reader.feed(wire)
    return not frames


@pytest.mark.parametrize("frame", TYPICAL, ids=lambda f: type(f).__name__)
def test_every_single_bit_error_is_rejected(frame):
    wire = bytearray(P.encode(frame))
    body_bits = 8 * (len(wire) - 1)  # every bit of the frame but its delimiter
    for bit in range(body_bits):
        corrupted = bytearray(wire)
        corrupted[bit // 8] ^= 1 << (bit % 8)
        assert _rejected(bytes(corrupted)), f"bit {bit} flipped in {frame} was accepted"


@settings(max_examples=3000, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from(TYPICAL), st.integers(1, 16), st.data())
def test_every_burst_up_to_16_bits_is_rejected(frame, length, data):
    wire = bytearray(P.encode(frame))
    bits = 8 * (len(wire) - 1)
    start = data.draw(st.integers(0, bits - length))
    # A burst of `length` bits: the first and last bits flipped, any pattern between.
    inner = data.draw(st.integers(0, max(0, 2 ** max(0, length - 2) - 1)))
    pattern = 1 | (inner << 1) | (1 << (length - 1))
    for i in range(length):
        if pattern >> i & 1:
            bit = start + i
            wire[bit // 8] ^= 1 << (bit % 8)
    assert _rejected(bytes(wire))


@settings(deadline=None)
@given(st.binary(min_size=1, max_size=300), st.lists(FRAMES, min_size=1, max_size=5), st.integers(1, 40))
def test_reader_resynchronizes_after_garbage(garbage, frames, chunk):
    reader = P.FrameReader()
    stream = garbage + b"\x00" + b"".join(P.encode(f) for f in frames)
    got = []
    for i in range(0, len(stream), chunk):  # arbitrary read sizes, as a serial port delivers
        got += reader.feed(stream[i : i + chunk])
    # Every real frame comes out; the garbage is at most counted, never returned as something else.
    assert got[-len(frames):] == [type(f)(*vars(f).values()) for f in got[-len(frames):]]
    assert [type(f) for f in got[-len(frames):]] == [type(f) for f in frames]
    assert all(g.seq == f.seq for g, f in zip(got[-len(frames):], frames))


def test_reader_drops_overlong_packets_and_counts_them():
    reader = P.FrameReader()
    out = reader.feed(b"\x01" * 500 + b"\x00" + P.encode(P.Stream(9, 1)))
    assert [type(f) for f in out] == [P.Stream]
    assert reader.errors == 1


def test_sequence_gaps_are_counted():
    reader = P.FrameReader()
    seqs = [65533, 65534, 65535, 0, 3, 4, 10]  # wraps at 65536; gaps of 2 and 5
    for s in seqs:
        reader.feed(P.encode(P.Sample(s)))
    assert reader.frames == len(seqs)
    assert reader.lost == 2 + 5


def test_unwrap16_follows_counters_across_the_wrap():
    full = 32000
    rng = random.Random(3)
    for _ in range(5000):
        true = full + rng.randint(-3000, 3000)
        full = P.unwrap16(full, true & 0xFFFF)
        assert full == true


def test_bandwidth_in_the_document_matches_the_frames():
    text = (__import__("pathlib").Path(__file__).parents[1] / "docs" / "protocol.md").read_text()
    assert P.wire_size(P.Sample) == 22 and "**22 B**" in text
    assert P.wire_size(P.Command) == 12 and "**12 B**" in text
    # 1 Mbaud 8N1: 100 bytes per ms; both directions fit a 1 kHz loop with room.
    assert P.wire_size(P.Sample) * 10 / P.DEFAULT_BAUD < 0.3e-3
