"""The WaveFront real-time codec (tonguevis.live.rtc3d) against hand-built bytes.

The bytes here are written with :mod:`struct` from the layout in shared/LIVE.md, never
with the encoder under test, so that encoder and decoder cannot agree on a mistake.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tonguevis.errors import TonguevisError
from tonguevis.live.rtc3d import (
    BIG, LITTLE, MAX_PACKET_SIZE, MAX_SENSORS, LiveProtocolError, PacketReader, PacketType, decode_data,
    encode_6d_frame, encode_command, read_capture,
)

# LIVE.md's worked example, big-endian.
COMMAND_HEX = "0000001e 00000001 53747265616d4672616d657320416c6c4672616d6573"
DATA_HEX = ("00000064 00000003 00000001 00000058 00000004 000004d2 00000000004c4b40 00000002 "
            "3f800000 00000000 00000000 00000000 41280000 c0100000 41f00000 3dcccccd" + " ffffffff" * 8)


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace(" ", ""))


def item(o: str, q=(1.0, 0.0, 0.0, 0.0), xyz=(0.0, 0.0, 0.0), rms=0.0) -> bytes:
    return struct.pack(f"{o}8f", *q, *xyz, rms)


MISSING = b"\xff" * 32


def component(o: str, ctype: int, frame: int, stamp: int, body: bytes) -> bytes:
    return struct.pack(f"{o}IIIQ", 20 + len(body), ctype, frame, stamp) + body


def sixd(o: str, frame: int, stamp: int, items: list[bytes]) -> bytes:
    return component(o, 4, frame, stamp, struct.pack(f"{o}I", len(items)) + b"".join(items))


def packet(o: str, ptype: int, payload: bytes) -> bytes:
    return struct.pack(f"{o}II", 8 + len(payload), ptype) + payload


def data_packet(o: str, components: list[bytes]) -> bytes:
    return packet(o, 3, struct.pack(f"{o}I", len(components)) + b"".join(components))


def test_worked_example_command_bytes():
    expected = hexbytes(COMMAND_HEX)
    assert len(expected) == 30
    assert encode_command("StreamFrames AllFrames") == expected
    (p,) = PacketReader().feed(expected)
    assert p.type == PacketType.COMMAND and p.text == "StreamFrames AllFrames"


def test_worked_example_data_bytes():
    expected = hexbytes(DATA_HEX)
    assert len(expected) == 100
    (p,) = PacketReader().feed(expected)
    assert p.type == PacketType.DATA and p.size == 100
    frame = decode_data(p.payload).sixd
    assert frame.frame == 1234 and frame.timestamp_us == 5_000_000 and frame.n_sensors == 2
    np.testing.assert_array_equal(frame.positions[0], np.float32([10.5, -2.25, 30.0]))
    np.testing.assert_array_equal(frame.quaternions[0], [1, 0, 0, 0])
    assert frame.rms[0] == np.float32(0.1)
    assert np.isnan(frame.positions[1]).all() and np.isnan(frame.quaternions[1]).all() and np.isnan(frame.rms[1])
    # The encoder writes exactly these bytes (the missing slot as 32 x 0xFF).
    built = encode_6d_frame(1234, 5_000_000, [[10.5, -2.25, 30.0], [np.nan] * 3], [[1, 0, 0, 0], [1, 0, 0, 0]],
                            [0.1, 0.0])
    assert built == expected


@pytest.mark.parametrize("o", [BIG, LITTLE])
def test_both_byte_orders(o):
    raw = data_packet(o, [sixd(o, 7, 123456789012, [item(o, (0.5, 0.5, -0.5, 0.5), (1.25, -3.5, 200.0), 0.25),
                                                    MISSING, item(o, xyz=(-1.0, 2.0, -3.0))])])
    (p,) = PacketReader(o, detect=False).feed(raw)
    frame = decode_data(p.payload, o).sixd
    assert frame.frame == 7 and frame.timestamp_us == 123456789012
    np.testing.assert_array_equal(frame.positions[[0, 2]], [[1.25, -3.5, 200.0], [-1.0, 2.0, -3.0]])
    np.testing.assert_array_equal(frame.quaternions[0], [0.5, 0.5, -0.5, 0.5])
    assert np.isnan(frame.positions[1]).all()
    assert encode_6d_frame(7, 123456789012, frame.positions, frame.quaternions, frame.rms, o) == raw
    # Read in the other order, the same bytes are not this frame.
    other = LITTLE if o == BIG else BIG
    with pytest.raises(LiveProtocolError):
        PacketReader(other, detect=False).feed(raw)


def test_first_packet_detects_the_byte_order():
    raw = packet(LITTLE, 1, b"Version 1.0")
    reader = PacketReader(BIG)
    (p,) = reader.feed(raw)
    assert p.text == "Version 1.0" and reader.detected == LITTLE and reader.byte_order == LITTLE
    # Only the first packet decides: a later big-endian packet is refused, not silently flipped.
    with pytest.raises(LiveProtocolError):
        reader.feed(packet(BIG, 1, b"Bye"))


def test_a_slot_without_a_finite_position_is_missing_as_a_whole():
    o = BIG
    half = struct.pack(f"{o}8f", 1, 0, 0, 0, np.nan, 2.0, 3.0, 0.1)
    frame = decode_data(data_packet(o, [sixd(o, 1, 0, [half, item(o, xyz=(4, 5, 6))])])[8:], o).sixd
    assert np.isnan(frame.positions[0]).all() and np.isnan(frame.quaternions[0]).all()
    np.testing.assert_array_equal(frame.positions[1], [4, 5, 6])


@pytest.mark.parametrize("o", [BIG, LITTLE])
def test_unknown_component_types_are_skipped_by_their_size(o):
    analog = component(o, 2, 9, 1, struct.pack(f"{o}I", 3) + b"\x01" * 13)  # odd size: no alignment assumed
    strange = component(o, 77, 9, 1, b"")
    three_d = component(o, 1, 9, 1, struct.pack(f"{o}I1f", 1, 5.0) + b"\x00" * 8)
    wanted = sixd(o, 9, 1, [item(o, xyz=(1, 2, 3))])
    raw = data_packet(o, [analog, strange, wanted, three_d])
    decoded = decode_data(raw[8:], o)
    assert decoded.skipped == [2, 77, 1]
    np.testing.assert_array_equal(decoded.sixd.positions, [[1, 2, 3]])
    # A frame with no 6D component is not an error: there is just no frame in it.
    assert decode_data(data_packet(o, [analog])[8:], o).sixd is None


def test_split_and_merged_reads():
    o = BIG
    packets = [packet(o, 1, b"Version 1.0")]
    packets += [data_packet(o, [sixd(o, k, 10_000 * k, [item(o, xyz=(k, -k, 2 * k)), MISSING])]) for k in (1, 2, 3)]
    stream = b"".join(packets)
    # One byte at a time.
    reader = PacketReader(o)
    out = [p for b in range(len(stream)) for p in reader.feed(stream[b:b + 1])]
    assert [p.type for p in out] == [1, 3, 3, 3] and reader.pending == 0
    # Everything in one read, then in uneven chunks that cut headers and items.
    assert len(PacketReader(o).feed(stream)) == 4
    reader = PacketReader(o)
    cuts = [0, 3, 9, 20, 57, 58, 140, len(stream)]
    out = [p for a, b in zip(cuts[:-1], cuts[1:]) for p in reader.feed(stream[a:b])]
    frames = [decode_data(p.payload, o).sixd for p in out[1:]]
    assert [f.frame for f in frames] == [1, 2, 3]
    np.testing.assert_array_equal(frames[2].positions[0], [3, -3, 6])
    assert np.isnan(frames[2].positions[1]).all()
    # A packet and a half in one read: one out, the half pending and described.
    reader = PacketReader(o)
    first, second = len(packets[0]), len(packets[1])
    assert len(reader.feed(stream[:first + second // 2])) == 1
    assert reader.pending == second // 2 and reader.pending_description() == f"{second // 2} of a {second}-byte packet"


def test_a_size_smaller_than_the_header_is_refused():
    with pytest.raises(LiveProtocolError, match="smaller than the 8-byte header"):
        PacketReader(detect=False).feed(struct.pack(">II", 4, 1))
    with pytest.raises(LiveProtocolError):
        PacketReader(detect=True).feed(struct.pack(">II", 0, 1))


def test_a_size_beyond_the_maximum_is_refused_at_the_header():
    assert issubclass(LiveProtocolError, TonguevisError)
    # MAX_PACKET_SIZE holds the largest frame (16 components of 64 sensors) and no more.
    assert MAX_PACKET_SIZE == 8 + 4 + 16 * (20 + 4 + MAX_SENSORS * 32)
    for size in (MAX_PACKET_SIZE + 1, 2**31, 2**32 - 1):
        reader = PacketReader(detect=False)
        with pytest.raises(LiveProtocolError, match="exceeds the maximum"):
            reader.feed(struct.pack(">II", size, 3))  # only the header: refused before any payload arrives
    # The largest allowed size is accepted (and waits for its bytes).
    reader = PacketReader(detect=False)
    assert reader.feed(struct.pack(">II", MAX_PACKET_SIZE, 2)) == [] and reader.pending == 8


def test_truncated_and_inconsistent_frames_are_refused():
    o = BIG
    good = sixd(o, 1, 0, [item(o), item(o)])
    cases = {
        "no component count": b"\x00\x00",
        "claims 17 components": struct.pack(">I", 17),
        "a component header needs": struct.pack(">I", 1) + good[:12],
        "claims 200 bytes": struct.pack(">I", 1) + struct.pack(">IIIQ", 200, 4, 1, 0) + good[20:],
        "claims 19 bytes": struct.pack(">I", 1) + struct.pack(">IIIQ", 19, 4, 1, 0),
        "claims 3 items": struct.pack(">I", 1) + good[:20] + struct.pack(">I", 3) + good[24:],
        "bytes after its 1 components": struct.pack(">I", 1) + good + b"\x00",
        "has no item count": struct.pack(">I", 1) + struct.pack(">IIIQ", 20, 4, 1, 0),
    }
    for message, payload in cases.items():
        with pytest.raises(LiveProtocolError, match=message):
            decode_data(payload, o)
    too_many = struct.pack(">I", 1) + component(o, 4, 1, 0, struct.pack(">I", MAX_SENSORS + 1)
                                                 + item(o) * (MAX_SENSORS + 1))
    with pytest.raises(LiveProtocolError, match="at most 64 items"):
        decode_data(too_many, o)
    with pytest.raises(LiveProtocolError):
        encode_6d_frame(1, 0, np.zeros((MAX_SENSORS + 1, 3)))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-500, 500, width=32), st.floats(-500, 500, width=32),
                          st.floats(-500, 500, width=32), st.booleans()), min_size=0, max_size=20),
       st.sampled_from([BIG, LITTLE]), st.integers(0, 2**32 - 1), st.integers(0, 2**64 - 1),
       st.lists(st.integers(1, 97), max_size=6))
def test_round_trip_any_frame_any_split(sensors, o, frame, stamp, cuts):
    positions = np.array([[x, y, z] if present else [np.nan] * 3 for x, y, z, present in sensors]).reshape(-1, 3)
    raw = encode_6d_frame(frame, stamp, positions, byte_order=o) * 2
    reader = PacketReader(o, detect=False)
    bounds = sorted({0, len(raw), *[c % len(raw) for c in cuts]})
    out = [p for a, b in zip(bounds[:-1], bounds[1:]) for p in reader.feed(raw[a:b])]
    assert len(out) == 2 and reader.pending == 0
    decoded = decode_data(out[1].payload, o).sixd
    assert decoded.frame == frame and decoded.timestamp_us == stamp
    np.testing.assert_array_equal(decoded.positions, positions.astype(np.float32))


def test_read_capture_follows_a_byte_order_switch_and_leaves_a_cut_packet_out():
    big, little = BIG, LITTLE
    data = (packet(big, 1, b"Version 1.0") + packet(little, 1, b"Byte order set to LittleEndian")
            + data_packet(little, [sixd(little, 5, 50, [item(little, xyz=(1, 2, 3))])])
            + data_packet(little, [sixd(little, 6, 60, [item(little, xyz=(4, 5, 6))])])[:30])
    packets, frames = read_capture(data)
    assert [p.text for p in packets[:2]] == ["Version 1.0", "Byte order set to LittleEndian"]
    assert len(packets) == 3 and [f.frame for f in frames] == [5]
    np.testing.assert_array_equal(frames[0].positions, [[1, 2, 3]])
    with pytest.raises(LiveProtocolError, match="exceeds the maximum"):
        read_capture(struct.pack(">II", MAX_PACKET_SIZE + 1, 3) + struct.pack("<II", MAX_PACKET_SIZE + 1, 3))
