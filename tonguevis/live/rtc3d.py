"""The NDI WaveFront real-time ("RTC3D") wire format: packets, commands and 6D data frames.

Written from the protocol facts in ``shared/LIVE.md`` (no third-party code):

* Every packet is ``uint32 size`` (the whole packet, this 8-byte header included),
  ``uint32 type`` (:class:`PacketType`), then the payload.  Big-endian unless the
  client sent ``SetByteOrder LittleEndian``.
* Command, reply and error payloads are ASCII text; XML payloads are text too.
* A data frame's payload is ``uint32`` component count, then the components:
  ``uint32 size`` (its 20-byte header included), ``uint32 type``
  (:class:`ComponentType`), ``uint32 frame``, ``uint64 timestamp`` (µs), then
  ``uint32 item count`` and the items.  A 6D item is 32 bytes: float32 q0, qx, qy,
  qz, x, y, z (mm), rms error (mm); a missing sensor is 32 bytes of 0xFF (NaN).  The
  item's index is the sensor's *slot*; the stream carries no sensor id.  Component
  types other than 6D are skipped by their size.

Nothing here trusts a size field: :class:`PacketReader` refuses a packet larger than
:data:`MAX_PACKET_SIZE` (or smaller than its header) as soon as the 8 header bytes are
in, and grows its buffer only with bytes that actually arrived, so a broken or hostile
peer cannot make it allocate more than one packet's worth.

Byte order is a one-character :mod:`struct` prefix: ``">"`` big-endian, ``"<"`` little.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from tonguevis.errors import TonguevisError

BIG = ">"
LITTLE = "<"
DEFAULT_PORT = 3030
HEADER_SIZE = 8
COMPONENT_HEADER_SIZE = 20
ITEM_6D_SIZE = 32
#: The most sensor slots one 6D component may hold (the NDI Wave has 16 ports; 64 leaves room).
MAX_SENSORS = 64
#: The most components a data frame may hold (WaveFront sends one, 6D).
MAX_COMPONENTS = 16
#: The largest packet accepted: a data frame of MAX_COMPONENTS components of MAX_SENSORS
#: 32-byte items each (33,164 bytes).  6D frames from a real Wave are at most 556 bytes (16
#: sensors); the same cap bounds XML and text packets (a parameter list of 64 sensors fits).
MAX_PACKET_SIZE = HEADER_SIZE + 4 + MAX_COMPONENTS * (COMPONENT_HEADER_SIZE + 4 + MAX_SENSORS * ITEM_6D_SIZE)


class LiveProtocolError(TonguevisError):
    """A peer sent bytes that are not the RTC3D protocol (bad size, truncated packet, bad frame)."""


class PacketType(IntEnum):
    ERROR = 0
    COMMAND = 1
    XML = 2
    DATA = 3
    NODATA = 4
    C3D = 5


class ComponentType(IntEnum):
    POSITION_3D = 1
    ANALOG = 2
    FORCE = 3
    SIXD = 4
    EVENT = 5


def _order(byte_order: str) -> str:
    if byte_order not in (BIG, LITTLE):
        raise ValueError(f"byte order must be '>' or '<', not {byte_order!r}")
    return byte_order


@dataclass(frozen=True)
class Packet:
    """One packet: its :class:`PacketType` (an int, as unknown types are kept) and payload bytes."""

    type: int
    payload: bytes

    @property
    def text(self) -> str:
        """The payload as text (commands, replies, errors, XML): ASCII, trailing NULs and blanks removed."""
        return self.payload.rstrip(b"\x00").decode("ascii", errors="replace").strip()

    @property
    def size(self) -> int:
        return HEADER_SIZE + len(self.payload)


def encode_packet(ptype: int, payload: bytes, byte_order: str = BIG) -> bytes:
    """The bytes of one packet: size (header included), type, payload."""
    size = HEADER_SIZE + len(payload)
    if size > MAX_PACKET_SIZE:
        raise LiveProtocolError(f"packet of {size} bytes exceeds the maximum of {MAX_PACKET_SIZE}")
    return struct.pack(f"{_order(byte_order)}II", size, int(ptype)) + payload


def encode_command(text: str, byte_order: str = BIG, ptype: int = PacketType.COMMAND) -> bytes:
    """A command (or reply, or with ``ptype=PacketType.ERROR`` an error) packet holding ASCII ``text``."""
    return encode_packet(ptype, text.encode("ascii"), byte_order)


@dataclass
class Frame6D:
    """One 6D component decoded: the sensors of one frame, by slot.

    frame : the device's frame number.
    timestamp_us : the device's time stamp in microseconds.
    positions : (S, 3) float32 mm, NaN rows for missing sensors.
    quaternions : (S, 4) float32 q0 qx qy qz (NaN when missing).
    rms : (S,) float32 mm (NaN when missing).
    """

    frame: int
    timestamp_us: int
    positions: np.ndarray
    quaternions: np.ndarray
    rms: np.ndarray

    @property
    def n_sensors(self) -> int:
        return int(len(self.positions))


@dataclass
class DataFrame:
    """A decoded data packet: its 6D component (None if it had none) and the types skipped."""

    sixd: Frame6D | None
    skipped: list[int] = field(default_factory=list)


def encode_6d_items(positions: np.ndarray, quaternions: np.ndarray | None = None, rms: np.ndarray | None = None,
                    byte_order: str = BIG) -> bytes:
    """The items of a 6D component: (S, 3) mm positions, (S, 4) quaternions, (S,) rms.

    A slot whose position is not finite is written as 32 bytes of 0xFF (missing);
    missing quaternions default to NaN, rms to 0.
    """
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    n = len(positions)
    items = np.empty((n, 8), dtype=np.float32)
    items[:, 0:4] = np.nan if quaternions is None else np.asarray(quaternions, dtype=np.float64).reshape(n, 4)
    items[:, 4:7] = positions
    items[:, 7] = 0.0 if rms is None else np.asarray(rms, dtype=np.float64).reshape(n)
    raw = np.frombuffer(items.astype(f"{_order(byte_order)}f4").tobytes(), dtype=np.uint8).reshape(n, 32).copy()
    raw[~np.all(np.isfinite(positions), axis=1)] = 0xFF
    return raw.tobytes()


def encode_6d_component(frame: int, timestamp_us: int, positions, quaternions=None, rms=None,
                        byte_order: str = BIG) -> bytes:
    """One 6D component (header, item count, items) of ``positions`` (S, 3) mm; see :func:`encode_6d_items`."""
    items = encode_6d_items(positions, quaternions, rms, byte_order)
    n = len(items) // ITEM_6D_SIZE
    if n > MAX_SENSORS:
        raise LiveProtocolError(f"{n} sensors exceed the protocol cap of {MAX_SENSORS}")
    size = COMPONENT_HEADER_SIZE + 4 + len(items)
    return struct.pack(f"{_order(byte_order)}IIIQI", size, ComponentType.SIXD, frame & 0xFFFFFFFF,
                       timestamp_us, n) + items


def encode_data_packet(components: list[bytes], byte_order: str = BIG) -> bytes:
    """A data packet holding already encoded ``components``."""
    payload = struct.pack(f"{_order(byte_order)}I", len(components)) + b"".join(components)
    return encode_packet(PacketType.DATA, payload, byte_order)


def encode_6d_frame(frame: int, timestamp_us: int, positions, quaternions=None, rms=None,
                    byte_order: str = BIG) -> bytes:
    """A whole data packet with one 6D component (what WaveFront sends)."""
    return encode_data_packet([encode_6d_component(frame, timestamp_us, positions, quaternions, rms, byte_order)],
                              byte_order)


def decode_data(payload: bytes, byte_order: str = BIG) -> DataFrame:
    """Decode a data packet's payload; raises :class:`LiveProtocolError` naming what is wrong.

    The first 6D component is returned; other component types (and further 6D
    components) are skipped by their size and listed in ``skipped``.
    """
    o = _order(byte_order)
    view = memoryview(payload)
    if len(view) < 4:
        raise LiveProtocolError(f"data packet of {len(view)} payload bytes has no component count")
    (count,) = struct.unpack_from(f"{o}I", view, 0)
    if count > MAX_COMPONENTS:
        raise LiveProtocolError(f"data packet claims {count} components (at most {MAX_COMPONENTS})")
    pos, sixd, skipped = 4, None, []
    for k in range(count):
        if len(view) - pos < COMPONENT_HEADER_SIZE:
            raise LiveProtocolError(f"component {k + 1} of {count}: {len(view) - pos} bytes left, "
                                    f"a component header needs {COMPONENT_HEADER_SIZE}")
        size, ctype, frame, stamp = struct.unpack_from(f"{o}IIIQ", view, pos)
        if size < COMPONENT_HEADER_SIZE or size > len(view) - pos:
            raise LiveProtocolError(f"component {k + 1} of {count} claims {size} bytes; "
                                    f"{len(view) - pos} remain in the packet (its header alone is 20)")
        if ctype == ComponentType.SIXD and sixd is None:
            sixd = _decode_6d(view[pos:pos + size], o, frame, stamp)
        else:
            skipped.append(int(ctype))
        pos += size
    if pos != len(view):
        raise LiveProtocolError(f"data packet has {len(view) - pos} bytes after its {count} components")
    return DataFrame(sixd=sixd, skipped=skipped)


def _decode_6d(view: memoryview, o: str, frame: int, stamp: int) -> Frame6D:
    if len(view) < COMPONENT_HEADER_SIZE + 4:
        raise LiveProtocolError(f"6D component of {len(view)} bytes has no item count")
    (n,) = struct.unpack_from(f"{o}I", view, COMPONENT_HEADER_SIZE)
    expected = COMPONENT_HEADER_SIZE + 4 + ITEM_6D_SIZE * n
    if n > MAX_SENSORS or len(view) != expected:
        raise LiveProtocolError(f"6D component of {len(view)} bytes claims {n} items "
                                f"(that needs {expected} bytes; at most {MAX_SENSORS} items)")
    items = np.frombuffer(view, dtype=f"{o}f4", count=8 * n, offset=COMPONENT_HEADER_SIZE + 4)
    items = items.reshape(n, 8).astype(np.float32)
    # A slot without a finite position is missing as a whole (its rotation and rms too).
    items[~np.all(np.isfinite(items[:, 4:7]), axis=1)] = np.nan
    return Frame6D(frame=int(frame), timestamp_us=int(stamp), positions=items[:, 4:7].copy(),
                   quaternions=items[:, 0:4].copy(), rms=items[:, 7].copy())


class PacketReader:
    """Bytes in, whole packets out: handles packets split across reads and several in one read.

    ``feed(data)`` returns the packets completed by ``data``.  A size field smaller than
    the 8-byte header or larger than ``max_size`` (default :data:`MAX_PACKET_SIZE`) raises
    :class:`LiveProtocolError` at once; after that the stream cannot be resynchronised and
    the reader must be :meth:`reset` with a new connection.

    byte_order : ``">"`` or ``"<"``; change it with :attr:`byte_order` (after SetByteOrder).
    detect : when the very first header is impossible in ``byte_order`` but plausible in the
        other order, take the other order (the default order of current WaveFront versions
        is not known; see :attr:`detected`).  Only the first packet decides.
    """

    def __init__(self, byte_order: str = BIG, max_size: int = MAX_PACKET_SIZE, detect: bool = True):
        self.byte_order = _order(byte_order)
        self.max_size = int(max_size)
        self.detect = detect
        self.detected: str | None = None
        self._buffer = bytearray()
        self._first = True

    def reset(self) -> None:
        """Forget buffered bytes (a new connection)."""
        self._buffer.clear()
        self._first = True

    @property
    def pending(self) -> int:
        """Bytes received that do not yet make a whole packet."""
        return len(self._buffer)

    def pending_description(self) -> str:
        """What the buffered partial packet is, for an error message."""
        if len(self._buffer) < HEADER_SIZE:
            return f"{len(self._buffer)} bytes of a packet header"
        size, _ = struct.unpack_from(f"{self.byte_order}II", self._buffer, 0)
        return f"{len(self._buffer)} of a {size}-byte packet"

    def _plausible(self, order: str) -> bool:
        size, ptype = struct.unpack_from(f"{order}II", self._buffer, 0)
        return HEADER_SIZE <= size <= self.max_size and ptype <= max(PacketType)

    def feed(self, data: bytes) -> list[Packet]:
        self._buffer += data
        packets = []
        while len(self._buffer) >= HEADER_SIZE:
            if self._first and self.detect and not self._plausible(self.byte_order):
                other = LITTLE if self.byte_order == BIG else BIG
                if self._plausible(other):
                    self.byte_order = self.detected = other
            size, ptype = struct.unpack_from(f"{self.byte_order}II", self._buffer, 0)
            if size < HEADER_SIZE:
                raise LiveProtocolError(f"packet size field {size} is smaller than the {HEADER_SIZE}-byte header")
            if size > self.max_size:
                raise LiveProtocolError(f"packet size field {size} exceeds the maximum of {self.max_size} bytes "
                                        f"(type field {ptype}; wrong byte order or not an RTC3D peer?)")
            self._first = False
            if len(self._buffer) < size:
                break
            packets.append(Packet(int(ptype), bytes(self._buffer[HEADER_SIZE:size])))
            del self._buffer[:size]
        return packets


def read_capture(data: bytes, byte_order: str = BIG) -> tuple[list[Packet], list[Frame6D]]:
    """(every packet, the 6D frames) of the raw bytes a client received (a capture file's content).

    A header impossible in the current byte order but plausible in the other switches the
    order from that packet on (the reply to SetByteOrder may come in either); a cut last
    packet is left out; a size beyond :data:`MAX_PACKET_SIZE` raises :class:`LiveProtocolError`.
    """
    reader = PacketReader(byte_order, detect=False)
    packets, frames = [], []
    view = memoryview(data)
    pos = 0
    while len(view) - pos >= HEADER_SIZE:
        header = bytes(view[pos:pos + HEADER_SIZE])
        other = LITTLE if reader.byte_order == BIG else BIG
        if not _plausible_header(header, reader.byte_order) and _plausible_header(header, other):
            reader.byte_order = other
        got = reader.feed(header)  # the size is checked before the payload is looked at
        (size,) = struct.unpack_from(f"{reader.byte_order}I", header)
        if pos + size > len(view):
            break
        got = got or reader.feed(bytes(view[pos + HEADER_SIZE:pos + size]))
        pos += size
        packet = got[0]
        packets.append(packet)
        if packet.type == PacketType.DATA:
            sixd = decode_data(packet.payload, reader.byte_order).sixd
            if sixd is not None:
                frames.append(sixd)
    return packets, frames


def _plausible_header(header: bytes, order: str) -> bool:
    size, ptype = struct.unpack(f"{order}II", header)
    return HEADER_SIZE <= size <= MAX_PACKET_SIZE and ptype <= max(PacketType)
