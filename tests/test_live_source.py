"""Live sources: the WaveFront client against the replay server (reconnects, faults), the recording source."""

from __future__ import annotations

import socket
import struct
import threading
import time

import numpy as np
import pytest

from tonguevis.live.rtc3d import LITTLE
from tonguevis.live.server import Faults, ReplayServer
from tonguevis.live.source import RecordingSource, WaveFrontSource, parse_parameters, recording_frames
from tonguevis.paths import DEMO_RECORDING
from tonguevis.workflows import open_recording

from tests.test_live_server import synthetic


@pytest.fixture(scope="module")
def demo():
    return open_recording(DEMO_RECORDING)


def collect(source, count: int, timeout: float = 5.0) -> list:
    frames, deadline = [], time.monotonic() + timeout
    while len(frames) < count and time.monotonic() < deadline:
        f = source.get(0.05)
        if f is not None:
            frames.append(f)
    return frames


def expected_positions(rec, frame_numbers) -> np.ndarray:
    positions, _, _ = recording_frames(rec)
    return positions[(np.asarray(frame_numbers) - 1) % rec.n_samples]


def test_end_to_end_on_the_demo(demo):
    events = []
    with ReplayServer(demo, speed=10.0) as server:
        source = WaveFrontSource("127.0.0.1", server.port, on_event=events.append).start()
        frames = collect(source, 150)
        newest = source.latest()
        source.close()
        time.sleep(0.1)  # let the server read the goodbye
        commands = [text for _, text in server.commands]
    assert source.sensor_names == demo.sensor_names and source.sensor_ids == demo.metadata["ndi_ids"]
    assert source.axes == "x,y,z"
    numbers = [f.frame for f in frames]
    assert numbers == list(range(1, 151))
    np.testing.assert_array_equal(np.stack([f.positions for f in frames]), expected_positions(demo, numbers))
    assert all(f.positions.dtype == np.float64 and f.positions.shape == (8, 3) for f in frames)
    assert newest.frame >= frames[-1].frame
    assert all(0 < f.arrival_s <= time.perf_counter() for f in frames)
    assert commands[:3] == ["Version 1.0", "SendParameters All", "StreamFrames AllFrames"]
    assert commands[-2:] == ["StreamFrames Stop", "Bye"]
    st = source.status()
    assert st.state == "finished" and st.reconnects == 0 and st.errors == [] and st.dropped == 0
    assert any("connected" in e for e in events)


def test_little_endian_on_request(demo):
    with ReplayServer(demo, speed=10.0) as server:
        source = WaveFrontSource("127.0.0.1", server.port, byte_order=LITTLE).start()
        frames = collect(source, 20)
        source.close()
        assert ("SetByteOrder LittleEndian" in [t for _, t in server.commands])
    np.testing.assert_array_equal(np.stack([f.positions for f in frames]),
                                  expected_positions(demo, [f.frame for f in frames]))


def test_reconnects_after_a_disconnect_in_the_middle_of_a_packet(demo):
    with ReplayServer(demo, speed=10.0, faults=Faults(cut_after=20)) as server:
        source = WaveFrontSource("127.0.0.1", server.port, backoff=0.05).start()
        frames = collect(source, 60)
        source.close()
        assert server.connections == 2
    st = source.status()
    assert st.reconnects == 1 and len(frames) == 60
    assert "in the middle of a packet" in st.errors[0]
    # The frames after the reconnection are right, and the gap is counted as missed.
    assert st.missed == frames[-1].frame - len(frames) > 0
    np.testing.assert_array_equal(np.stack([f.positions for f in frames]),
                                  expected_positions(demo, [f.frame for f in frames]))


def test_capture_keeps_the_raw_bytes_of_each_connection(demo, tmp_path):
    from tonguevis.live.rtc3d import PacketType, read_capture

    with ReplayServer(demo, speed=10.0, faults=Faults(cut_after=10)) as server:
        source = WaveFrontSource("127.0.0.1", server.port, backoff=0.05, byte_order=LITTLE,
                                 capture=tmp_path / "raw.rtc3d").start()
        frames = collect(source, 25)
        source.close()
    assert source.captured == [tmp_path / "raw.rtc3d", tmp_path / "raw_2.rtc3d"]
    first, second = (read_capture(p.read_bytes()) for p in source.captured)
    # The first connection: the replies (the first in the new order), 10 frames, and half a packet left out.
    assert [p.type for p in first[0][:3]] == [PacketType.COMMAND, PacketType.COMMAND, PacketType.XML]
    assert [f.frame for f in first[1]] == [f.frame for f in frames[:10]]
    assert (tmp_path / "raw.rtc3d").stat().st_size > sum(p.size for p in first[0])
    captured = first[1] + second[1]
    assert [f.frame for f in captured[:25]] == [f.frame for f in frames]
    np.testing.assert_array_equal(np.stack([f.positions for f in captured[:25]]), np.stack([f.positions for f in frames]))


def test_reconnects_after_a_stall(demo):
    with ReplayServer(demo, speed=10.0, faults=Faults(stall_after=10, stall_seconds=5.0)) as server:
        source = WaveFrontSource("127.0.0.1", server.port, stall_timeout=0.3, backoff=0.05).start()
        frames = collect(source, 30)
        source.close()
    st = source.status()
    assert len(frames) == 30 and st.reconnects == 1
    assert "stalled" in st.errors[0]
    assert [f.frame for f in frames[:10]] == list(range(1, 11)) and frames[10].frame > 11


def test_a_malformed_packet_is_reported_and_the_connection_reopened(demo):
    with ReplayServer(demo, speed=10.0, faults=Faults(bad_size_after=5)) as server:
        source = WaveFrontSource("127.0.0.1", server.port, backoff=0.05).start()
        frames = collect(source, 15)
        source.close()
    st = source.status()
    assert len(frames) == 15 and st.reconnects == 1
    assert "malformed packet" in st.errors[0] and "exceeds the maximum" in st.errors[0]


def test_a_hostile_peer_cannot_make_it_allocate_or_crash():
    """A peer announcing a 4 GB packet is refused at the header; the client gives up cleanly."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]
    stop = threading.Event()

    def hostile():
        listener.settimeout(0.1)
        while not stop.is_set():
            try:
                conn, _ = listener.accept()
            except socket.timeout:
                continue
            conn.sendall(struct.pack(">II", 2**32 - 1, 3) + b"\x00" * 100)
            time.sleep(0.05)
            conn.close()

    thread = threading.Thread(target=hostile, daemon=True)
    thread.start()
    try:
        source = WaveFrontSource("127.0.0.1", port, max_retries=2, backoff=0.01, command_timeout=0.2).start()
        deadline = time.monotonic() + 5
        while not source.finished and time.monotonic() < deadline:
            time.sleep(0.02)
        st = source.status()
        assert st.state == "failed" and st.frames == 0 and st.reconnects == 2
        assert "exceeds the maximum" in st.errors[0] and "gave up" in st.errors[-1]
        assert source.get(0) is None and list(source.frames(timeout=0.01)) == []
        source.close()
    finally:
        stop.set()
        thread.join()
        listener.close()


def test_a_device_that_sends_other_components_and_no_replies():
    """Frames with an analog component before the 6D one are used (the analog skipped, said once); a device
    that answers no command still streams."""
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]

    def device():
        conn, _ = listener.accept()
        for k in range(1, 6):
            analog = struct.pack(">IIIQI", 28, 2, k, 0, 1) + b"\0" * 4
            sixd = struct.pack(">IIIQI", 56, 4, k, 1000 * k, 1) + struct.pack(">8f", 1, 0, 0, 0, k, 2, 3, 0.5)
            payload = struct.pack(">I", 2) + analog + sixd
            conn.sendall(struct.pack(">II", 8 + len(payload), 3) + payload)
        time.sleep(1.0)
        conn.close()

    thread = threading.Thread(target=device, daemon=True)
    thread.start()
    events = []
    source = WaveFrontSource("127.0.0.1", port, command_timeout=0.1, on_event=events.append).start()
    frames = collect(source, 5)
    source.close()
    listener.close()
    assert [f.frame for f in frames] == [1, 2, 3, 4, 5]
    np.testing.assert_array_equal([f.positions[0, 0] for f in frames], [1, 2, 3, 4, 5])
    assert frames[2].timestamp_s == 0.003
    assert sum("types [2]" in e for e in events) == 1


def test_nothing_listening_gives_up_after_the_bounded_tries():
    sock = socket.create_server(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()  # nobody listens there now
    source = WaveFrontSource("127.0.0.1", port, max_retries=3, backoff=0.01).start()
    deadline = time.monotonic() + 5
    while not source.finished and time.monotonic() < deadline:
        time.sleep(0.02)
    st = source.status()
    assert st.state == "failed" and st.reconnects == 3 and len(st.errors) == 5  # 4 refusals and "gave up"
    source.close()


def test_missing_sensors_and_device_drops_arrive_as_nan_and_missed(demo):
    with ReplayServer(demo, speed=10.0, faults=Faults(nan_slots=(1, 5), drop_every=3)) as server:
        source = WaveFrontSource("127.0.0.1", server.port).start()
        frames = collect(source, 20)
        source.close()
    assert all(np.isnan(f.positions[[1, 5]]).all() and np.isnan(f.quaternions[[1, 5]]).all() for f in frames)
    assert all(np.isfinite(f.positions[[0, 2, 3, 4, 6, 7]]).all() for f in frames)
    assert all(f.frame % 3 for f in frames)
    st = source.status()
    assert st.missed == source.latest().frame - st.frames > 0


def test_the_queue_is_bounded_and_counts_what_it_drops():
    rec = synthetic(n=40)
    source = RecordingSource(rec, speed=40.0, queue_size=10).start()
    deadline = time.monotonic() + 5
    while not source.finished and time.monotonic() < deadline:
        time.sleep(0.01)
    st = source.status()
    assert st.frames == 40 and st.dropped == 30
    kept = list(source.frames(timeout=0.01))
    assert [f.frame for f in kept] == list(range(1, 11))  # the oldest are kept: the newest are dropped
    assert source.latest().frame == 40  # the display still sees the newest


def test_recording_source_plays_the_recording(demo):
    source = RecordingSource(demo, speed=50.0).start()
    frames = list(source.frames(timeout=0.1))
    source.close()
    assert [f.frame for f in frames] == list(range(1, demo.n_samples + 1))
    np.testing.assert_array_equal(np.stack([f.positions for f in frames]), expected_positions(demo, range(1, 1763)))
    np.testing.assert_array_equal([f.timestamp_s for f in frames], demo.times)
    assert source.sensor_names == demo.sensor_names and source.axes == "x,y,z"


def test_recording_source_loops_until_closed():
    rec = synthetic(n=5)
    source = RecordingSource(rec, speed=20.0, loop=True, queue_size=None).start()
    deadline = time.monotonic() + 5
    while (source.latest() is None or source.latest().frame < 12) and time.monotonic() < deadline:
        time.sleep(0.01)
    source.close()
    assert source.latest().frame >= 12 and source.finished
    with pytest.raises(RuntimeError, match="latest"):
        source.get(0)


def test_parameters_of_an_unknown_schema_are_ignored():
    assert parse_parameters("not xml <") == (None, None, None)
    assert parse_parameters("<Params><Rate>100</Rate></Params>") == (None, None, None)
    names, ids, axes = parse_parameters('<A><Tool port="3" name="TT"/><Tool port="x"/></A>')
    assert names == ["TT", "slot1"] and ids is None and axes is None
