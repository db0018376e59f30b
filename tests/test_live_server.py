"""The replay server (tonguevis.live.server) spoken to with raw sockets and hand-checked packets."""

from __future__ import annotations

import socket
import struct
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from tonguevis.io.recording import Recording
from tonguevis.live.rtc3d import BIG, LITTLE, LiveProtocolError, PacketReader, PacketType, decode_data, encode_command
from tonguevis.live.server import Faults, ReplayServer
from tonguevis.live.source import WaveFrontSource
from tonguevis.paths import DEMO_RECORDING
from tonguevis.workflows import open_recording

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "ema"


def synthetic(n: int = 30, rate: float = 100.0, names=("TT", "TD", "REF1")) -> Recording:
    """n samples of len(names) sensors on a known path (metres), quaternions w-x-y-z."""
    t = np.arange(n) / rate + 0.5
    sensors = {name: np.column_stack([0.01 * k + 0.001 * np.arange(n), -0.002 * k + 0 * t, 0.03 + 1e-4 * np.arange(n)])
               for k, name in enumerate(names)}
    quats = {name: np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)) for name in names}
    return Recording(rate=rate, times=t, sensors=sensors, orientations=quats,
                     metadata={"format": "test", "file": "synthetic", "original_unit": "m",
                               "orientation_kind": "quaternion_wxyz"})


class Client:
    """A bare client: send commands, read packets (with a deadline)."""

    def __init__(self, port: int, order: str = BIG):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=2.0)
        self.reader = PacketReader(order, detect=False)
        self.pending: list = []
        self.error = None  # a protocol error, raised once the packets before it are read

    def send(self, text: str) -> None:
        self.sock.sendall(encode_command(text, self.reader.byte_order))

    def packet(self, timeout: float = 2.0):
        deadline = time.monotonic() + timeout
        while not self.pending:
            if self.error is not None:
                raise self.error
            self.sock.settimeout(max(deadline - time.monotonic(), 0.01))
            data = self.sock.recv(65536)
            if not data:
                return None
            # The packets before a bad header come first, its error after them: one recv can hold both (under
            # load), and the reader, fed the chunk whole, raised for it all (the good packets lost: a flake).
            try:
                for start in range(0, len(data), 8):
                    self.pending += self.reader.feed(data[start:start + 8])
            except LiveProtocolError as exc:
                self.error = exc
        return self.pending.pop(0)

    def frames(self, count: int, timeout: float = 5.0) -> list:
        out = []
        deadline = time.monotonic() + timeout
        while len(out) < count and time.monotonic() < deadline:
            try:
                p = self.packet(max(deadline - time.monotonic(), 0.01))
            except TimeoutError:
                break
            if p is None:  # closed
                break
            if p.type == PacketType.DATA:
                out.append(decode_data(p.payload, self.reader.byte_order).sixd)
        return out

    def close(self):
        self.sock.close()


@pytest.fixture
def demo():
    return open_recording(DEMO_RECORDING)


def test_commands_and_replies(demo):
    with ReplayServer(demo, speed=10.0) as server:
        assert server.host == "127.0.0.1" and server._listener.getsockname()[0] == "127.0.0.1"
        c = Client(server.port)
        c.send("Version 1.0")
        reply = c.packet()
        assert reply.type == PacketType.COMMAND and reply.text == "Version 1.0"
        c.send("sendparameters all")  # case-insensitive
        xml = c.packet()
        assert xml.type == PacketType.XML
        root = ET.fromstring(xml.text)
        slots = root.findall(".//Sensor")
        assert [s.get("name") for s in slots] == demo.sensor_names
        assert [int(s.get("id")) for s in slots] == demo.metadata["ndi_ids"]
        assert root.find("Axes").text == "x,y,z"  # the demo is read with its axes
        c.send("Frobnicate now")
        error = c.packet()
        assert error.type == PacketType.ERROR and error.text.startswith("Error-")
        c.send("SendCurrentFrame")
        frame = decode_data(c.packet().payload).sixd
        assert frame.n_sensors == len(demo.sensor_names) and frame.frame >= 1
        k = frame.frame - 1
        np.testing.assert_array_equal(frame.positions, np.stack([demo.sensors[s][k] * 1000 for s in demo.sensor_names])
                                      .astype(np.float32))
        assert frame.timestamp_us == round(demo.times[k] * 1e6)
        # Little-endian from the reply to SetByteOrder on.
        c.send("SetByteOrder LittleEndian")
        c.reader.byte_order = LITTLE
        assert c.packet().text == "Byte order set to LittleEndian"
        c.send("SendCurrentFrame")
        assert decode_data(c.packet().payload, LITTLE).sixd.n_sensors == 8
        c.send("Bye")
        assert c.packet() is None  # the server hangs up after Bye
        c.close()
        assert [text for _, text in server.commands][-1] == "Bye"


def test_stream_modes_and_stop(demo):
    with ReplayServer(demo, speed=10.0) as server:
        c = Client(server.port)
        c.send("StreamFrames AllFrames")
        numbers = [f.frame for f in c.frames(20)]
        assert numbers == list(range(numbers[0], numbers[0] + 20))
        for command, step in (("StreamFrames FrequencyDivisor:5", 5), ("StreamFrames Frequency:25", 4)):  # 100/25
            c.send(command)
            steps = np.diff([f.frame for f in c.frames(60)])
            # Packets of the former mode still on the way come first; the last 30 are all of the new one.
            assert set(steps[-30:]) == {step}
        c.send("StreamFrames Stop")
        c.frames(3, timeout=0.2)  # drain what was in flight
        c.send("Version 1.0")
        while (p := c.packet()) is not None and p.type == PacketType.DATA:
            pass
        assert p.type == PacketType.COMMAND  # after Stop only the reply comes: no data
        c.send("StreamFrames Frequency:abc")
        assert c.packet().type == PacketType.ERROR
        c.close()


def test_the_stream_keeps_the_recordings_rate():
    """Frames leave as they fall due, not all at once: in 0.3 s of a 100 Hz recording far fewer than 100 come."""
    rec = synthetic(n=500)
    with ReplayServer(rec) as server:
        c = Client(server.port)
        c.send("StreamFrames AllFrames")
        start = time.monotonic()
        frames = c.frames(1000, timeout=0.3)
        elapsed = time.monotonic() - start
        assert 1 <= len(frames) <= 100 * elapsed + 10
        c.close()


def test_loop_continues_numbers_and_times():
    rec = synthetic(n=12)
    with ReplayServer(rec, speed=2.0, loop=True) as server:
        c = Client(server.port)
        c.send("StreamFrames AllFrames")
        frames = c.frames(30)
        c.close()
    assert [f.frame for f in frames] == list(range(1, 31))
    stamps = np.array([f.timestamp_us for f in frames])
    assert np.all(np.diff(stamps) == 10_000)  # 100 Hz across the loop's seam
    assert stamps[0] == 500_000  # the recording's own first time
    np.testing.assert_array_equal(frames[12].positions, frames[0].positions)
    np.testing.assert_array_equal(frames[13].positions, frames[1].positions)
    assert not np.array_equal(frames[1].positions, frames[0].positions)


def test_a_clock_starting_below_zero_is_shifted_to_zero():
    rec = synthetic(n=5)
    rec.times = rec.times - 0.53  # -0.03 ... 0.01 s
    server = ReplayServer(rec)
    stamps = [decode_data(PacketReader().feed(server.frame_packet(k))[0].payload).sixd.timestamp_us for k in range(5)]
    assert stamps == [0, 10_000, 20_000, 30_000, 40_000]


def test_without_loop_the_stream_ends():
    rec = synthetic(n=10)
    with ReplayServer(rec, speed=5.0) as server:
        c = Client(server.port)
        c.send("StreamFrames AllFrames")
        frames = c.frames(20, timeout=1.0)
        assert server.finished.wait(2.0)
        c.send("SendCurrentFrame")
        assert c.packet().type == PacketType.NODATA
        c.close()
    assert [f.frame for f in frames] == list(range(1, 11))


def test_faults_drop_nan_and_bad_size():
    rec = synthetic(n=200)
    with ReplayServer(rec, speed=5.0, faults=Faults(drop_every=4, nan_slots=(1,), nan_every=2,
                                                    bad_size_after=20)) as server:
        c = Client(server.port)
        c.send("StreamFrames AllFrames")
        frames = c.frames(20)
        assert all(f.frame % 4 for f in frames)  # every 4th frame dropped
        for f in frames:
            assert np.isnan(f.positions[1]).all() == (f.frame % 2 == 0)
            assert np.isfinite(f.positions[[0, 2]]).all()
        with pytest.raises(Exception, match="exceeds the maximum"):
            c.frames(1)
        c.close()


def test_a_cut_packet_then_a_clean_second_connection():
    rec = synthetic(n=2000)
    with ReplayServer(rec, speed=5.0, faults=Faults(cut_after=5)) as server:
        c = Client(server.port)
        c.send("StreamFrames AllFrames")
        assert len(c.frames(10, timeout=1.0)) == 5
        assert c.packet() is None and 0 < c.reader.pending < 100  # closed with half a packet read
        c.close()
        c = Client(server.port)  # first_connection_only: the second is clean
        c.send("StreamFrames AllFrames")
        assert len(c.frames(10)) == 10
        c.close()


def test_a_stall_sends_nothing_for_a_while_then_resumes_live():
    rec = synthetic(n=300)
    with ReplayServer(rec, speed=2.0, faults=Faults(stall_after=3, stall_seconds=0.5)) as server:
        c = Client(server.port)
        c.send("StreamFrames AllFrames")
        frames = c.frames(6)
        c.close()
    numbers = [f.frame for f in frames]
    assert numbers[:3] == [1, 2, 3]
    assert numbers[3] - numbers[2] > 10  # it resumed at the live frame, as a device does


def test_client_and_server_end_to_end_on_a_real_ndi_wave_export():
    path = SHARED / "ndi_wave" / "Example3.tsv"
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared third-party data is not here)")
    rec = open_recording(path, {})
    with ReplayServer(rec, speed=10.0) as server:
        source = WaveFrontSource("127.0.0.1", server.port, stall_timeout=1.0).start()
        frames = []
        deadline = time.monotonic() + 5.0
        while len(frames) < rec.n_samples and time.monotonic() < deadline:
            f = source.get(0.2)
            if f is not None:
                frames.append(f)
        source.close()
    assert source.sensor_ids == rec.metadata["ndi_ids"]
    assert [f.frame for f in frames] == list(range(1, rec.n_samples + 1))
    wire = np.stack([f.positions for f in frames])
    expected = np.stack([rec.sensors[s] * 1000 for s in rec.sensor_names], axis=1).astype(np.float32)
    np.testing.assert_array_equal(wire, expected)  # NaN where the export has a missing sample
    assert np.isnan(expected).any()
    stamps = np.array([f.timestamp_s for f in frames])
    np.testing.assert_allclose(stamps, rec.times, atol=5e-7)


def test_refuses_more_sensors_than_the_protocol_holds():
    from tonguevis.live.rtc3d import LiveProtocolError

    with pytest.raises(LiveProtocolError, match="64"):
        ReplayServer(synthetic(n=3, names=[f"S{k}" for k in range(65)]))


def test_listens_on_every_network_only_when_asked():
    rec = synthetic(n=3)
    server = ReplayServer(rec, host="0.0.0.0")
    port = server.start()
    try:
        assert server._listener.getsockname() == ("0.0.0.0", port)
        sock = socket.create_connection(("127.0.0.1", port), timeout=2.0)
        sock.sendall(struct.pack(">II", 8 + 11, 1) + b"Version 1.0")
        assert PacketReader().feed(sock.recv(100))[0].text == "Version 1.0"
        sock.close()
    finally:
        server.stop()



def test_the_replay_server_counts_the_clients_connected_now():
    """Issue 37: the server kept reporting "2 connection(s)" after both clients had left."""
    import socket
    import time

    from tonguevis.live.server import serve_until_done

    with ReplayServer(synthetic(n=60)) as server:
        clients = [socket.create_connection(("127.0.0.1", server.port)) for _ in range(2)]
        deadline = time.monotonic() + 5
        while server.connected < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert server.connected == 2
        for sock in clients:
            sock.close()
        while server.connected and time.monotonic() < deadline:
            time.sleep(0.02)
        assert server.connected == 0 and server.connections == 2
        said = []

        def report(text):  # the first report ends the wait
            said.append(text)
            server.finished.set()

        serve_until_done(server, report=report, interval=0.01)
        assert "0 client(s) connected (2 in all)" in said[0], said
