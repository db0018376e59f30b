"""Live sources of EMA frames: one interface, whatever the device.

A :class:`Source` delivers :class:`LiveFrame` objects from a background thread:

* :meth:`Source.latest` — the newest frame only (what a display draws; older ones are
  simply superseded, so a slow consumer never builds a backlog);
* :meth:`Source.get` / :meth:`Source.frames` — every frame in order, from a bounded queue
  (what a recorder writes); when the consumer falls behind the queue is full and new
  frames are counted as dropped (``status().dropped``) instead of growing memory.

Sources:

* :class:`WaveFrontSource` — the NDI Wave's WaveFront real-time interface over TCP
  (:mod:`tonguevis.live.rtc3d`).  A stalled connection (no bytes for ``stall_timeout``
  seconds) or a dropped one is noticed and reconnected with exponential backoff, up to
  ``max_retries`` failed attempts in a row; a malformed packet is reported (status,
  ``on_event``) and the connection reopened.  Nothing is raised into the consumer.
* :class:`RecordingSource` — a tonguevis :class:`~tonguevis.io.recording.Recording`
  played at its own rate, in-process (tests, the app's demo).

The Carstens AG501 real-time server (cs5recorder, TCP 30303, text commands and a
fixed binary record) would be a third subclass of :class:`ThreadedSource`; it is not
built, because nothing about its record layout can be checked without the device.

Units: positions in millimetres in the device's frame (as the wire carries them),
times in seconds.
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
import xml.etree.ElementTree as ET
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tonguevis.live.rtc3d import (
    BIG, DEFAULT_PORT, LiveProtocolError, PacketReader, PacketType, decode_data, encode_command,
)

from tonguevis._logging import logger

#: Frames the recorder's queue holds before new ones are dropped (60 s at 100 Hz).
QUEUE_FRAMES = 6000


@dataclass(frozen=True)
class LiveFrame:
    """One frame of every sensor slot.

    frame : the device's frame number.
    timestamp_s : the device's time stamp in seconds.
    arrival_s : :func:`time.perf_counter` when the bytes were read from the socket (or made).
    positions : (S, 3) float64 mm (float32 values from the wire), NaN rows for missing sensors.
    quaternions : (S, 4) float64 q0 qx qy qz, NaN when missing or unknown.
    rms : (S,) float64 mm, NaN when missing.
    """

    frame: int
    timestamp_s: float
    arrival_s: float
    positions: np.ndarray
    quaternions: np.ndarray
    rms: np.ndarray

    @property
    def n_sensors(self) -> int:
        return int(len(self.positions))


@dataclass
class SourceStatus:
    """A snapshot of a source's health (every count since :meth:`Source.start`).

    state : "idle", "connecting", "streaming", "reconnecting", "finished" or "failed".
    frames : frames received.  dropped : frames lost because the queue was full.
    missed : frames the device numbered but never sent (gaps in the frame numbers).
    reconnects : reconnection attempts (after a stall, a drop, a bad packet or a refused connection).
    errors : problems met (newest last, at most 20).  message : the last event.
    """

    state: str = "idle"
    frames: int = 0
    dropped: int = 0
    missed: int = 0
    reconnects: int = 0
    errors: list[str] = field(default_factory=list)
    message: str = ""


class Source(ABC):
    """What every live source offers (see the module docstring)."""

    #: Slot names when the device told them (else None: slots are 0, 1, ...).
    sensor_names: list[str] | None = None
    #: Slot ids when the device told them (NDI Wave port ids), else None.
    sensor_ids: list[int] | None = None
    #: "x,y,z" when the device said its positions are already in tonguevis's frame (x anterior,
    #: y left, z up; the replay server of a recording read with its axes), else None (device frame).
    axes: str | None = None
    #: Whether :meth:`get` hands every frame in order (else only :meth:`latest` is kept).
    queued: bool = True

    @abstractmethod
    def start(self) -> "Source":
        """Connect and begin delivering frames (in the background); returns self."""

    @abstractmethod
    def latest(self) -> LiveFrame | None:
        """The newest frame received, or None before the first."""

    @abstractmethod
    def get(self, timeout: float | None = None) -> LiveFrame | None:
        """The next frame in order (None when none came within ``timeout`` seconds)."""

    @abstractmethod
    def status(self) -> SourceStatus:
        """A copy of the current :class:`SourceStatus`."""

    @abstractmethod
    def close(self) -> None:
        """Stop delivering, say goodbye to the device, free the connection."""

    @property
    def finished(self) -> bool:
        """Whether no more frames will come (the end of a file, given up, closed)."""
        return self.status().state in ("finished", "failed")

    def frames(self, timeout: float = 0.5) -> Iterator[LiveFrame]:
        """Every frame in order until the source finishes (waits ``timeout`` at a time)."""
        while True:
            frame = self.get(timeout)
            if frame is not None:
                yield frame
            elif self.finished:
                frame = self.get(0)  # one that arrived between the two checks
                if frame is None:
                    return
                yield frame

    def __enter__(self) -> "Source":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()


class ThreadedSource(Source):
    """A source whose frames come from a reader thread running :meth:`_run`.

    queue_size : frames kept for :meth:`get` (None: no queue, :meth:`latest` only).
    on_event : called (from the reader thread) with a one-line message on every
        connection event and error; must not block.
    """

    def __init__(self, queue_size: int | None = QUEUE_FRAMES, on_event: Callable[[str], None] | None = None):
        self._queue: queue.Queue[LiveFrame] | None = queue.Queue(queue_size) if queue_size else None
        self._latest: LiveFrame | None = None
        self._status = SourceStatus()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._on_event = on_event
        self._errors: deque[str] = deque(maxlen=20)
        self._last_frame_number: int | None = None

    # --- for the reader thread -------------------------------------------------------------------------
    def _event(self, message: str, error: bool = False) -> None:
        with self._lock:
            self._status.message = message
            if error:
                self._errors.append(message)
        # With a callback the consumer shows the message; the log then keeps it quiet (no double lines).
        level = logging.WARNING if error and self._on_event is None else logging.INFO
        logger.log(level, "live source: %s", message)
        if self._on_event is not None:
            try:
                self._on_event(message)
            except Exception:  # a consumer's callback must not kill the reader
                logger.exception("live source: on_event callback failed")

    def _set_state(self, state: str) -> None:
        with self._lock:
            self._status.state = state

    def _deliver(self, frame: LiveFrame) -> None:
        with self._lock:
            self._latest = frame
            self._status.frames += 1
            last = self._last_frame_number
            if last is not None and frame.frame > last + 1:
                self._status.missed += frame.frame - last - 1
            self._last_frame_number = frame.frame
        if self._queue is not None:
            try:
                self._queue.put_nowait(frame)
            except queue.Full:
                with self._lock:
                    self._status.dropped += 1

    @abstractmethod
    def _run(self) -> None:
        """Produce frames with :meth:`_deliver` until ``self._stop`` is set or the source ends."""

    def _main(self) -> None:
        try:
            self._run()
        except Exception as exc:  # never let the thread die silently: the consumer sees "failed"
            self._event(f"stopped by an unexpected error: {exc!r}", error=True)
            self._set_state("failed")
            logger.exception("live source crashed")

    # --- the interface ---------------------------------------------------------------------------------
    @property
    def queued(self) -> bool:
        return self._queue is not None

    def start(self) -> "ThreadedSource":
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._main, name=type(self).__name__, daemon=True)
            self._thread.start()
        return self

    def latest(self) -> LiveFrame | None:
        with self._lock:
            return self._latest

    def get(self, timeout: float | None = None) -> LiveFrame | None:
        if self._queue is None:
            raise RuntimeError("this source keeps no queue (queue_size=None): use latest()")
        try:
            return self._queue.get(timeout=timeout) if timeout != 0 else self._queue.get_nowait()
        except queue.Empty:
            return None

    def status(self) -> SourceStatus:
        with self._lock:
            snapshot = SourceStatus(**{**self._status.__dict__, "errors": list(self._errors)})
        return snapshot

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        with self._lock:
            if self._status.state not in ("failed",):
                self._status.state = "finished"


def _frame_from_6d(sixd, arrival: float) -> LiveFrame:
    return LiveFrame(frame=sixd.frame, timestamp_s=sixd.timestamp_us * 1e-6, arrival_s=arrival,
                     positions=sixd.positions.astype(np.float64), quaternions=sixd.quaternions.astype(np.float64),
                     rms=sixd.rms.astype(np.float64))


class _Stalled(Exception):
    pass


class _Closed(Exception):
    pass


def parse_parameters(text: str) -> tuple[list[str] | None, list[int] | None, str | None]:
    """(slot names, slot ids, axes) from a SendParameters XML reply, each None when it does not say.

    WaveFront's own schema is not known; this reads ``<Sensor>`` (or ``<Tool>``)
    elements in document order with a ``name`` and an ``id`` (or ``port``) attribute,
    and an ``<Axes>`` element, the layout :mod:`tonguevis.live.server` sends.
    """
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return None, None, None
    axes = next((e.text.strip() for e in root.iter() if e.tag.lower() == "axes" and e.text), None)
    elements = [e for e in root.iter() if e.tag.lower() in ("sensor", "tool")]
    if not elements:
        return None, None, axes
    names = [e.get("name") or f"slot{k}" for k, e in enumerate(elements)]
    try:
        ids = [int(e.get("id", e.get("port"))) for e in elements]
    except (TypeError, ValueError):
        ids = None
    return names, ids, axes


class WaveFrontSource(ThreadedSource):
    """An NDI Wave through its WaveFront real-time interface (TCP, RTC3D packets).

    host, port : the WaveFront machine (port 3030 by default).
    stall_timeout : seconds without a byte before the connection counts as stalled.
    max_retries : failed connection attempts in a row before giving up ("failed").
    backoff : first wait before reconnecting (s), doubled each failure up to ``max_backoff``.
    byte_order : ``">"`` (the protocol's default) or ``"<"``: asks with SetByteOrder when not big-endian.
    command_timeout : seconds to wait for a reply during the handshake.
    capture : a file path: every byte received is also written there, raw and flushed (the golden
        files a first session on real hardware gives; read them back with
        :func:`tonguevis.live.rtc3d.read_capture`).  Connection n > 1 goes to ``STEM_n.SUFFIX``.

    The handshake: ``Version 1.0``, ``SendParameters All`` (slot names when the reply
    lists them, see :func:`parse_parameters`), ``StreamFrames AllFrames``.  On
    :meth:`close`: ``StreamFrames Stop`` and ``Bye``.  An error reply to a handshake
    command is reported but not fatal (which commands a device requires is not known).
    """

    def __init__(self, host: str, port: int = DEFAULT_PORT, *, stall_timeout: float = 2.0, max_retries: int = 5,
                 backoff: float = 0.2, max_backoff: float = 5.0, byte_order: str = BIG, command_timeout: float = 2.0,
                 connect_timeout: float = 3.0, queue_size: int | None = QUEUE_FRAMES, capture=None,
                 on_event: Callable[[str], None] | None = None):
        super().__init__(queue_size=queue_size, on_event=on_event)
        self.host, self.port = host, int(port)
        self.stall_timeout = float(stall_timeout)
        self.max_retries = int(max_retries)
        self.backoff, self.max_backoff = float(backoff), float(max_backoff)
        self.byte_order = byte_order
        self.command_timeout = float(command_timeout)
        self.connect_timeout = float(connect_timeout)
        self.parameters_xml: str | None = None
        self.capture = None if capture is None else Path(capture)
        self.captured: list[Path] = []
        self._capture_file = None
        self._reader = PacketReader(byte_order)
        self._got = self._warned = False

    def __repr__(self) -> str:
        return f"WaveFrontSource({self.host!r}, {self.port})"

    def _run(self) -> None:
        failures = 0
        first = True
        while not self._stop.is_set():
            self._set_state("connecting" if first else "reconnecting")
            self._got = self._warned = False  # per connection
            sock = None
            try:
                sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout)
                sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self._event(f"connected to {self.host}:{self.port}")
                self._reader = PacketReader(BIG)  # the protocol's default until SetByteOrder
                self._open_capture()
                self._handshake(sock)
                self._set_state("streaming")
                self._stream(sock)
                if self._stop.is_set():
                    self._goodbye(sock)
                    break
            except (OSError, LiveProtocolError, _Stalled, _Closed) as exc:
                self._event(self._describe(exc), error=True)
            finally:
                if sock is not None:
                    sock.close()
                if self._capture_file is not None:
                    self._capture_file.close()
                    self._capture_file = None
            if self._stop.is_set():
                break
            failures = 0 if self._got else failures + 1
            if failures > self.max_retries:
                self._event(f"gave up after {self.max_retries} failed reconnection attempts", error=True)
                self._set_state("failed")
                return
            wait = min(self.backoff * 2 ** max(failures - 1, 0), self.max_backoff)
            with self._lock:
                self._status.reconnects += 1
            self._event(f"reconnecting in {wait:.1f} s (attempt {failures + 1} of {self.max_retries + 1})")
            first = False
            if self._stop.wait(wait):
                break
        self._set_state("finished")

    def _open_capture(self) -> None:
        if self.capture is None:
            return
        n = len(self.captured) + 1
        path = self.capture if n == 1 else self.capture.with_name(f"{self.capture.stem}_{n}{self.capture.suffix}")
        path.parent.mkdir(parents=True, exist_ok=True)
        self._capture_file = open(path, "wb")
        self.captured.append(path)

    def _describe(self, exc: Exception) -> str:
        where = f"{self.host}:{self.port}"
        if isinstance(exc, _Stalled):
            return f"{where}: no data for {self.stall_timeout:g} s (stalled connection)"
        if isinstance(exc, _Closed):
            return f"{where}: {exc}"
        if isinstance(exc, LiveProtocolError):
            return f"{where}: malformed packet: {exc}"
        return f"{where}: {exc.strerror or exc}" if isinstance(exc, OSError) else f"{where}: {exc}"

    def _send(self, sock: socket.socket, text: str) -> None:
        sock.sendall(encode_command(text, self._reader.byte_order))

    def _recv(self, sock: socket.socket, deadline: float) -> tuple[bytes, float]:
        """Bytes from ``sock`` (and their arrival time), polling so that close() is never kept waiting."""
        sock.settimeout(0.05)
        while True:
            try:
                data = sock.recv(65536)
            except socket.timeout:
                if self._stop.is_set():
                    return b"", time.perf_counter()
                if time.perf_counter() > deadline:
                    raise _Stalled() from None
                continue
            arrival = time.perf_counter()
            if self._capture_file is not None and data:
                self._capture_file.write(data)
                self._capture_file.flush()
            if not data:
                pending = self._reader.pending
                what = f" in the middle of a packet ({self._reader.pending_description()})" if pending else ""
                raise _Closed(f"connection closed by the device{what}")
            return data, arrival

    def _reply(self, sock: socket.socket, command: str, send: bool = True):
        """The next non-data packet after sending ``command`` (None if none came in time).

        Frames that come meanwhile (a device already streaming) are delivered, not lost.
        """
        if send:
            self._send(sock, command)
        deadline = time.perf_counter() + self.command_timeout
        while not self._stop.is_set():
            try:
                data, arrival = self._recv(sock, deadline)
            except _Stalled:
                self._event(f"no reply to {command!r} within {self.command_timeout:g} s")
                return None
            packets = self._reader.feed(data)
            for k, packet in enumerate(packets):
                if packet.type == PacketType.DATA:
                    self._data(packet, arrival)
                elif packet.type != PacketType.NODATA:
                    for later in packets[k + 1:]:  # frames right behind the reply
                        if later.type == PacketType.DATA:
                            self._data(later, arrival)
                    return packet
        return None

    def _data(self, packet, arrival: float) -> bool:
        """Decode and deliver a data packet; whether it held a frame."""
        decoded = decode_data(packet.payload, self._reader.byte_order)
        if decoded.skipped and not self._warned:
            # Said once per connection: WaveFront is said to send one 6D component only.
            self._warned = True
            self._event(f"frames hold components this source does not use (types "
                        f"{sorted(set(decoded.skipped))}; 4 = a further 6D one): skipped")
        if decoded.sixd is None:
            return False
        self._deliver(_frame_from_6d(decoded.sixd, arrival))
        self._got = True
        return True

    def _handshake(self, sock: socket.socket) -> None:
        if self.byte_order != BIG:
            # Asked in the default order; the reply may come in either (ours: the new one), so the
            # reader may still detect it, and from then on both directions are little-endian.
            self._send(sock, "SetByteOrder LittleEndian")
            self._reader.byte_order = self.byte_order
            reply = self._reply(sock, "SetByteOrder LittleEndian", send=False)
            if reply is not None and reply.type == PacketType.ERROR:
                self._event(f"'SetByteOrder LittleEndian' answered with an error: {reply.text}", error=True)
            self._reader.byte_order = self.byte_order
            self._reader.detected = None
        for command in ("Version 1.0", "SendParameters All"):
            reply = self._reply(sock, command)
            if reply is None:
                continue
            if reply.type == PacketType.ERROR:
                self._event(f"{command!r} answered with an error: {reply.text}", error=True)
            elif reply.type == PacketType.XML and command.startswith("SendParameters"):
                self.parameters_xml = reply.text
                names, ids, axes = parse_parameters(reply.text)
                if names is not None:
                    self.sensor_names, self.sensor_ids = names, ids
                self.axes = axes
        if self._reader.detected:
            self._event(f"the device speaks {'little' if self._reader.detected == '<' else 'big'}-endian")
        self._send(sock, "StreamFrames AllFrames")

    def _stream(self, sock: socket.socket) -> None:
        """Read and deliver frames until close() (returns) or a stall, a drop or a bad packet (raises)."""
        while not self._stop.is_set():
            data, arrival = self._recv(sock, time.perf_counter() + self.stall_timeout)
            if not data:  # close() asked us to stop
                break
            for packet in self._reader.feed(data):
                if packet.type == PacketType.DATA:
                    self._data(packet, arrival)
                elif packet.type == PacketType.ERROR:
                    self._event(f"device error: {packet.text}", error=True)

    def _goodbye(self, sock: socket.socket) -> None:
        try:
            self._send(sock, "StreamFrames Stop")
            self._send(sock, "Bye")
            sock.shutdown(socket.SHUT_WR)
        except OSError:
            pass  # the device is gone already: nothing to say goodbye to
        self._event(f"disconnected from {self.host}:{self.port}")


class RecordingSource(ThreadedSource):
    """A :class:`~tonguevis.io.recording.Recording` played at its own rate in-process (no socket).

    Frames carry the recording's sensors in its order (slot k = ``sensor_names[k]``),
    positions in mm rounded to float32 as on the wire, the sample times as time stamps
    and the sample index (from 1, continuing across loops) as frame number.

    speed : playback speed factor.  loop : start again at the end (else the source finishes).
    """

    def __init__(self, recording, *, speed: float = 1.0, loop: bool = False, queue_size: int | None = QUEUE_FRAMES,
                 on_event: Callable[[str], None] | None = None):
        super().__init__(queue_size=queue_size, on_event=on_event)
        if speed <= 0:
            raise ValueError(f"speed must be positive, not {speed}")
        self.recording = recording
        self.speed, self.loop = float(speed), bool(loop)
        self.sensor_names = list(recording.sensor_names)
        ids = recording.metadata.get("ndi_ids")
        self.sensor_ids = list(ids) if ids is not None and len(ids) == len(self.sensor_names) else None
        self.axes = "x,y,z" if recording.metadata.get("frame") == "tonguevis" else None
        self._frames = recording_frames(recording)

    def _run(self) -> None:
        positions, quaternions, times = self._frames
        n = len(times)
        if n == 0:
            self._set_state("finished")
            return
        self._set_state("streaming")
        period = times[-1] - times[0] + 1.0 / self.recording.rate
        start = time.perf_counter()
        k = 0
        while not self._stop.is_set():
            i, lap = k % n, k // n
            if lap and not self.loop:
                break
            t = times[i] - times[0] + lap * period
            wait = start + t / self.speed - time.perf_counter()
            if wait > 0 and self._stop.wait(wait):
                break
            self._deliver(LiveFrame(frame=k + 1, timestamp_s=times[i] + lap * period, arrival_s=time.perf_counter(),
                                    positions=positions[i], quaternions=quaternions[i],
                                    rms=np.where(np.isfinite(positions[i, :, 0]), 0.0, np.nan)))
            k += 1
        self._set_state("finished")


def recording_frames(recording) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((N, S, 3) mm positions, (N, S, 4) quaternions, (N,) times s) of a recording, as a stream carries them.

    Positions are the recording's metres times 1000, rounded to float32 (the wire's
    precision); a sample with any non-finite coordinate is missing as a whole.
    Quaternions are the w-x-y-z orientations when the recording has them, else NaN.
    """
    names = recording.sensor_names
    n = recording.n_samples
    positions = np.stack([np.asarray(recording.sensors[s], dtype=np.float64) * 1000.0 for s in names], axis=1) \
        if names else np.zeros((n, 0, 3))
    positions = positions.astype(np.float32).astype(np.float64)
    quaternions = np.full((n, len(names), 4), np.nan)
    if recording.metadata.get("orientation_kind", "quaternion_wxyz") == "quaternion_wxyz":
        for k, name in enumerate(names):
            q = recording.orientations.get(name)
            if q is not None and np.shape(q) == (n, 4):
                quaternions[:, k] = q
    quaternions = quaternions.astype(np.float32).astype(np.float64)
    missing = ~np.all(np.isfinite(positions), axis=2)
    positions[missing] = np.nan
    quaternions[missing] = np.nan
    return positions, quaternions, np.asarray(recording.times, dtype=np.float64)
