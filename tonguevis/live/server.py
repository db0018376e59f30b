"""A replay server that speaks the WaveFront real-time protocol from any recording tonguevis reads.

``ReplayServer(recording).start()`` listens (127.0.0.1 unless ``host`` says otherwise;
port 0 picks a free one, returned by :meth:`ReplayServer.start`) and serves any number of
clients, each in its own thread.  It plays the recording like a device: the clock starts
when the first client asks for frames and runs at the recording's own rate (times
``speed``) whether or not anyone listens, so a client that reconnects resumes at the
live frame, as with the real device.  Frame numbers count samples from 1 and keep
counting across loops; time stamps are the sample times (plus one recording length per
loop) in microseconds, shifted to start at 0 if the recording's clock starts below 0.  Positions are the recording's, in mm, slot k being the
recording's k-th sensor.

Commands answered (case-insensitive, as LIVE.md lists them): ``Version``,
``SendParameters`` (an XML list of the slots, ``<Sensor slot= id= name=>``, and ``<Axes>x,y,z</Axes>``
when the recording's positions are in tonguevis's frame),
``SendCurrentFrame``, ``StreamFrames AllFrames | Frequency:n | FrequencyDivisor:n | Stop``,
``SetByteOrder BigEndian|LittleEndian`` (the reply is already in the new order), ``Bye``.
Anything else gets an error packet ``Error-...``.  The reply texts are ours: the real
device's are not known.

:class:`Faults` injects what tests need: dropped frames, missing sensors, a stall, a
disconnect in the middle of a packet, a packet with an impossible size.
"""

from __future__ import annotations

import re
import socket
import struct
import threading
import time
from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

import numpy as np

from tonguevis.live.rtc3d import (
    BIG, LITTLE, MAX_PACKET_SIZE, MAX_SENSORS, LiveProtocolError, PacketReader, PacketType, encode_6d_frame,
    encode_command, encode_packet,
)
from tonguevis.live.source import recording_frames

from tonguevis._logging import logger
from tonguevis.sim.motion import frame_label


@dataclass
class Faults:
    """Faults a :class:`ReplayServer` injects (all off by default).

    drop_every : skip every n-th frame (its number is skipped too, so the client sees a gap).
    nan_slots : slots always sent as missing (32 bytes of 0xFF).
    nan_every : with ``nan_slots``, only every n-th frame (1: always).
    stall_after : after this many frames on a connection, send nothing for ``stall_seconds``
        (the connection stays open; commands are still read).
    cut_after : after this many frames on a connection, send half of the next data packet and close.
    bad_size_after : after this many frames on a connection, send a header whose size exceeds the maximum.
    first_connection_only : stalls, cuts and bad sizes happen on the first connection only
        (so a client that reconnects gets a clean stream).
    """

    drop_every: int = 0
    nan_slots: tuple[int, ...] = ()
    nan_every: int = 1
    stall_after: int | None = None
    stall_seconds: float = 3.0
    cut_after: int | None = None
    bad_size_after: int | None = None
    first_connection_only: bool = True


class ReplayServer:
    """Serve ``recording`` over the WaveFront real-time protocol (see the module docstring).

    recording : a :class:`~tonguevis.io.recording.Recording` (positions in metres).
    host, port : where to listen (port 0: any free port; :meth:`start` returns it).
    speed : playback speed factor.  loop : start again at the end; else after the last
        frame the server streams nothing more and :attr:`finished` is set.
    """

    def __init__(self, recording, host: str = "127.0.0.1", port: int = 0, *, speed: float = 1.0, loop: bool = False,
                 faults: Faults | None = None):
        if not speed > 0:
            raise ValueError(f"speed must be positive, not {speed}")
        if len(recording.sensor_names) > MAX_SENSORS:
            raise LiveProtocolError(f"{len(recording.sensor_names)} sensors exceed the protocol's {MAX_SENSORS}")
        self.recording = recording
        self.host, self.port = host, int(port)
        self.speed, self.loop = float(speed), bool(loop)
        self.faults = faults or Faults()
        self.positions, self.quaternions, self.times = recording_frames(recording)
        self.names = list(recording.sensor_names)
        ids = recording.metadata.get("ndi_ids")
        self.ids = list(ids) if ids is not None and len(ids) == len(self.names) else list(range(len(self.names)))
        self.period = (self.times[-1] - self.times[0] + 1.0 / recording.rate) if len(self.times) else 0.0
        # Time stamps are unsigned: a recording whose clock starts below 0 is shifted to start at 0.
        self.time_origin = min(float(self.times[0]), 0.0) if len(self.times) else 0.0
        self.finished = threading.Event()
        #: Connections accepted since the start (:attr:`connected`: those still open).
        self.connections = 0
        self.frames_sent = 0
        #: (connection number, command text) of every command received, in order (for tests and logs).
        self.commands: list[tuple[int, str]] = []
        self._clock: float | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._listener: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        self._clients: set[socket.socket] = set()

    # --- the clock -------------------------------------------------------------------------------------
    def _start_clock(self) -> None:
        with self._lock:
            if self._clock is None:
                self._clock = time.perf_counter()

    def current_index(self) -> int | None:
        """The global 0-based frame index due now (None before the clock starts or with no frames).

        Without ``loop`` the index stops at N (one past the last frame: the end).
        """
        n = len(self.times)
        if self._clock is None or n == 0:
            return None
        played = (time.perf_counter() - self._clock) * self.speed  # seconds of recording
        lap = int(played // self.period) if self.period > 0 else 0
        if not self.loop and lap >= 1:
            return n
        offset = played - lap * self.period
        i = int(np.searchsorted(self.times - self.times[0], offset, side="right")) - 1
        return lap * n + max(i, 0)

    def next_due(self, k: int) -> float:
        """perf_counter time at which global frame ``k`` is due (the clock must have started)."""
        n = len(self.times)
        return self._clock + (self.times[k % n] - self.times[0] + (k // n) * self.period) / self.speed

    def ended(self, k: int) -> bool:
        return not self.loop and k >= len(self.times)

    def frame_packet(self, k: int, byte_order: str = BIG, nan_slots: tuple[int, ...] = ()) -> bytes:
        """The data packet of global frame ``k`` (0-based): frame number k + 1."""
        n = len(self.times)
        i, lap = k % n, k // n
        positions = self.positions[i]
        if nan_slots:
            positions = positions.copy()
            positions[[s for s in nan_slots if s < len(positions)]] = np.nan
        stamp = int(round((self.times[i] - self.time_origin + lap * self.period) * 1e6))
        return encode_6d_frame(k + 1, stamp, positions, self.quaternions[i],
                               np.where(np.isfinite(positions[:, 0]), 0.0, np.nan), byte_order)

    def parameters_xml(self) -> str:
        rate = float(self.recording.rate)
        # Our own element: the positions are already in tonguevis's frame when the recording was read with its axes.
        axes = "<Axes>x,y,z</Axes>" if self.recording.metadata.get("frame") == "tonguevis" else ""
        sensors = "".join(f'<Sensor slot="{k}" id="{self.ids[k]}" name={quoteattr(str(name))}/>'
                          for k, name in enumerate(self.names))
        return (f'<?xml version="1.0" encoding="ascii"?><WaveFront server="tonguevis replay">'
                f'<Frequency>{rate:g}</Frequency>{axes}<Sensors count="{len(self.names)}">{sensors}</Sensors>'
                f'</WaveFront>')

    @property
    def connected(self) -> int:
        """Clients connected now (:attr:`connections` counts every one accepted since the start)."""
        with self._lock:
            return len(self._clients)

    @property
    def local_only(self) -> bool:
        """Whether only this machine can connect: listening on a loopback address (127.0.0.0/8, ::1)."""
        import ipaddress

        bound = self._listener.getsockname()[0] if self._listener is not None else self.host
        try:
            return ipaddress.ip_address(bound.split("%")[0]).is_loopback
        except ValueError:  # a host name before start(): its addresses decide
            try:
                infos = socket.getaddrinfo(bound, None)
            except OSError:
                return False
            return bool(infos) and all(ipaddress.ip_address(i[4][0].split("%")[0]).is_loopback for i in infos)

    # --- serving ---------------------------------------------------------------------------------------
    def start(self) -> int:
        """Listen and serve in background threads; returns the port bound."""
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        listener = socket.create_server((self.host, self.port), family=family)
        listener.settimeout(0.1)
        self._listener = listener
        self.port = listener.getsockname()[1]
        thread = threading.Thread(target=self._accept, name="ReplayServer", daemon=True)
        thread.start()
        self._threads.append(thread)
        if len(self.times):
            threading.Thread(target=self._watch_end, name="ReplayServer-end", daemon=True).start()
        return self.port

    def _watch_end(self) -> None:
        while not self._stop.wait(0.05):
            k = self.current_index()
            if k is not None and self.ended(k):
                self.finished.set()
                return

    def stop(self) -> None:
        """Stop listening and close every client connection."""
        self._stop.set()
        if self._listener is not None:
            self._listener.close()
        with self._lock:
            clients = list(self._clients)
        for sock in clients:
            try:
                sock.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        for thread in self._threads:
            thread.join(timeout=2.0)

    def __enter__(self) -> "ReplayServer":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                sock, address = self._listener.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self.connections += 1
                number = self.connections
                self._clients.add(sock)
            thread = threading.Thread(target=self._serve, args=(sock, number), name=f"ReplayClient{number}",
                                      daemon=True)
            thread.start()
            self._threads = [t for t in self._threads if t.is_alive()] + [thread]  # a long --loop sees many clients

    def _serve(self, sock: socket.socket, number: int) -> None:
        try:
            _Client(self, sock, number).run()
        except (OSError, LiveProtocolError) as exc:
            logger.info("replay server: client %d: %s", number, exc)
        finally:
            with self._lock:
                self._clients.discard(sock)
            sock.close()


class _Client:
    """One connection: its byte order, its streaming mode and its fault counters."""

    def __init__(self, server: ReplayServer, sock: socket.socket, number: int):
        self.server, self.sock, self.number = server, sock, number
        self.order = BIG
        self.reader = PacketReader(BIG, detect=False)
        self.divisor: int | None = None  # None: not streaming
        self.next_k: int | None = None
        self.sent = 0
        self.faulty = number == 1 or not server.faults.first_connection_only
        self.stalled_until = 0.0
        self.stalled = False

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def reply(self, text: str, ptype: int = PacketType.COMMAND) -> None:
        self.send(encode_command(text, self.order, ptype))

    def run(self) -> None:
        server = self.server
        while not server._stop.is_set():
            # Wait for a command, or until the next frame is due (so frames leave on time).
            wait = 0.05
            if self.divisor is not None and self.next_k is not None and not server.ended(self.next_k):
                now = time.perf_counter()
                wait = min(wait, max(max(server.next_due(self.next_k), self.stalled_until) - now, 0.0005))
            self.sock.settimeout(wait)
            try:
                data = self.sock.recv(4096)
                if not data:
                    return
                for packet in self.reader.feed(data):
                    if not self.command(packet):
                        return
            except socket.timeout:
                pass
            if self.divisor is not None and not self.stream():
                return

    def command(self, packet) -> bool:
        """Answer one packet; False when the connection is to end."""
        if packet.type != PacketType.COMMAND:
            self.reply(f"Error-expected a command packet, got type {packet.type}", PacketType.ERROR)
            return True
        text = packet.text
        with self.server._lock:
            self.server.commands.append((self.number, text))
        words = text.split()
        verb = words[0].lower() if words else ""
        arg = words[1] if len(words) > 1 else ""
        server = self.server
        if verb == "version":
            self.reply(f"Version {arg or '1.0'}")
        elif verb == "sendparameters":
            xml = server.parameters_xml().encode("ascii", "xmlcharrefreplace")  # a name such as "Zungenrücken"
            self.send(encode_packet(PacketType.XML, xml, self.order))
        elif verb == "setbyteorder":
            if arg.lower() in ("littleendian", "bigendian"):
                self.order = LITTLE if arg.lower() == "littleendian" else BIG
                self.reader.byte_order = self.order
                self.reply(f"Byte order set to {arg}")
            else:
                self.reply(f"Error-unknown byte order {arg!r}", PacketType.ERROR)
        elif verb == "sendcurrentframe":
            server._start_clock()
            k = server.current_index()
            if k is None or server.ended(k):
                self.send(encode_packet(PacketType.NODATA, b"", self.order))
            else:
                self.send(server.frame_packet(k, self.order))
        elif verb == "streamframes":
            return self.stream_command(arg)
        elif verb == "bye":
            return False
        else:
            self.reply(f"Error-unknown command {text[:60]!r}", PacketType.ERROR)
        return True

    def stream_command(self, arg: str) -> bool:
        server = self.server
        mode = arg.lower()
        match = re.fullmatch(r"(frequency|frequencydivisor):(\d+(?:\.\d*)?)", mode)
        if mode == "stop":
            self.divisor = None
            return True
        if mode in ("allframes", ""):
            divisor = 1
        elif match and float(match.group(2)) > 0:
            value = float(match.group(2))
            divisor = (max(1, round(server.recording.rate / value)) if match.group(1) == "frequency"
                       else max(1, int(value)))
        else:
            self.reply(f"Error-unknown StreamFrames mode {arg!r}", PacketType.ERROR)
            return True
        server._start_clock()
        self.divisor = divisor
        self.next_k = server.current_index()
        return True

    def stream(self) -> bool:
        """Send the frames due since the last call; False when the connection is to end."""
        server, faults = self.server, self.server.faults
        now = time.perf_counter()
        if now < self.stalled_until:
            return True
        due = server.current_index()
        if due is None:
            return True
        if self.stalled and self.stalled_until:
            # After a stall the device goes on with the live frame (what it measured meanwhile is gone).
            self.next_k = max(self.next_k, due)
            self.stalled_until = 0.0
        while self.next_k <= due and not server.ended(self.next_k):
            k = self.next_k
            self.next_k += 1
            if k % self.divisor or (faults.drop_every and (k + 1) % faults.drop_every == 0):
                continue
            if self.faulty and faults.stall_after is not None and self.sent == faults.stall_after \
                    and not self.stalled:
                self.stalled = True
                self.stalled_until = now + faults.stall_seconds
                self.next_k = k
                return True
            nan = faults.nan_slots if faults.nan_slots and (k + 1) % max(faults.nan_every, 1) == 0 else ()
            packet = server.frame_packet(k, self.order, nan)
            if self.faulty and faults.cut_after is not None and self.sent == faults.cut_after:
                self.send(packet[: len(packet) // 2])
                return False
            if self.faulty and faults.bad_size_after is not None and self.sent == faults.bad_size_after:
                self.send(struct.pack(f"{self.order}II", MAX_PACKET_SIZE + 1, PacketType.DATA))
                return False
            self.send(packet)
            self.sent += 1
            with server._lock:
                server.frames_sent += 1
        return True


def serve_until_done(server: ReplayServer, report=None, interval: float = 1.0) -> None:
    """Block until the server's recording ends (never with ``loop``); ``report(text)`` every ``interval`` s."""
    while not server.finished.wait(interval):
        if report is not None:
            k = server.current_index()
            n = len(server.times)
            where = "waiting for a client" if k is None else frame_label(min(k % n if server.loop else k, n - 1), n)
            report(f"{where}, {server.connected} client(s) connected ({server.connections} in all), "
                   f"{server.frames_sent} frames sent")

