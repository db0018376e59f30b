"""Recording a live stream: the TSV equals what was streamed, is readable while written, and opens everywhere."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from tonguevis.cli import main
from tonguevis.io.ndi_wave import read_ndi_wave
from tonguevis.live.recorder import TsvRecorder, free_path, record, write_head_corrected
from tonguevis.live.server import Faults, ReplayServer
from tonguevis.live.source import LiveFrame, WaveFrontSource, recording_frames
from tonguevis.paths import DEMO_RECORDING, REPO_DIR
from tonguevis.preprocess.correction import head_corrected
from tonguevis.workflows import open_recording

from tests.test_live_server import SHARED, synthetic


@pytest.fixture(scope="module")
def demo():
    return open_recording(DEMO_RECORDING)


def assert_equals_stream(recorded, streamed, nan_slots=()):
    """Every recorded sample equals the streamed one (float32 as on the wire), matched by frame number."""
    k = recorded.metadata["meas_id"].astype(int) - 1
    positions, quaternions, times = recording_frames(streamed)
    positions, quaternions = positions[k % streamed.n_samples], quaternions[k % streamed.n_samples]
    positions[:, list(nan_slots)] = np.nan
    quaternions[:, list(nan_slots)] = np.nan
    for slot, name in enumerate(recorded.sensor_names):
        got = (recorded.sensors[name] * 1000).astype(np.float32)
        np.testing.assert_array_equal(got, positions[:, slot].astype(np.float32), err_msg=name)
        np.testing.assert_array_equal(recorded.orientations[name].astype(np.float32),
                                      quaternions[:, slot].astype(np.float32), err_msg=name)
    np.testing.assert_allclose(recorded.times, times[k % streamed.n_samples], atol=5e-7)


def test_a_recorded_stream_equals_what_was_streamed(demo, tmp_path):
    with ReplayServer(demo, speed=10.0, faults=Faults(nan_slots=(2,), nan_every=4)) as server:
        source = WaveFrontSource("127.0.0.1", server.port).start()
        result = record(source, tmp_path / "sweep.tsv", seconds=0.6)
    assert result.path == tmp_path / "sweep.tsv" and result.frames > 100 and not result.interrupted
    raw = read_ndi_wave(result.path)  # the reader of NDI Wave exports reads it as one
    assert raw.metadata["ndi_ids"] == demo.metadata["ndi_ids"] and raw.n_samples == result.frames
    # Opened like any recording: the names and axes come from the sensor_map.json written beside it.
    rec = open_recording(result.path)
    assert rec.sensor_names == demo.sensor_names and rec.metadata["frame"] == "tonguevis"
    assert json.loads((tmp_path / "sensor_map.json").read_text())["sensors"]["TT"] == 1
    nan_rows = rec.metadata["meas_id"].astype(int) % 4 == 0
    assert nan_rows.any() and np.isnan(rec.sensors["TD"][nan_rows]).all()
    np.testing.assert_array_equal(rec.metadata["ndi_status"][nan_rows, 2], 119)
    k = rec.metadata["meas_id"].astype(int) - 1
    assert np.array_equal(k, np.arange(rec.n_samples))  # every frame from the first, none lost
    for name in demo.sensor_names:
        expected = (demo.sensors[name][k] * 1000).astype(np.float32)
        if name == "TD":
            expected[nan_rows] = np.nan
        np.testing.assert_array_equal((rec.sensors[name] * 1000).astype(np.float32), expected, err_msg=name)
    # The head-corrected version: the same as correcting the recorded file afterwards.
    assert result.head_corrected == tmp_path / "sweep_headcorrected.tsv"
    corrected = open_recording(result.head_corrected)
    again = head_corrected(rec)
    for name in demo.sensor_names:
        np.testing.assert_allclose(corrected.sensors[name], again.sensors[name], atol=1e-9)  # 6 decimals of mm
    assert any("head-corrected (REF1, REF2, REF3)" in note for note in result.notes)


def test_every_sample_and_quaternion_round_trips_exactly(tmp_path):
    rec = synthetic(n=40)
    rng = np.random.default_rng(3)
    for name in rec.sensor_names:  # values with all float32 digits, and some quaternions
        rec.sensors[name] = rng.uniform(-0.2, 0.2, (40, 3))
        rec.orientations[name] = rng.normal(size=(40, 4))
    rec.sensors["TD"][5] = np.nan
    with ReplayServer(rec, speed=10.0) as server:
        source = WaveFrontSource("127.0.0.1", server.port, stall_timeout=0.3, max_retries=1, backoff=0.05).start()
        result = record(source, tmp_path / "r.tsv")  # until the stream ends (the source gives up)
    assert result.status.state == "failed" and "gave up" in result.status.errors[-1]
    back = open_recording(result.path, {"TT": 0, "TD": 1, "REF1": 2})
    assert back.n_samples == 40
    assert_equals_stream(back, rec)
    assert any("1 head reference(s) (REF1); 3 are needed" in n for n in result.notes)
    assert result.head_corrected is None and not (tmp_path / "r_headcorrected.tsv").exists()


def test_rows_are_on_disk_as_they_arrive(tmp_path):
    """Nothing received is lost: the file reads back before the recorder is closed, and after a cut last row."""
    path = tmp_path / "live.tsv"
    recorder = TsvRecorder(path, ids=[4, 7])
    for k in range(5):
        recorder.write(LiveFrame(frame=k + 1, timestamp_s=0.01 * k, arrival_s=0.0,
                                 positions=np.array([[1.0 + k, 2.0, 3.0], [np.nan] * 3]),
                                 quaternions=np.full((2, 4), np.nan), rms=np.zeros(2)))
    early = read_ndi_wave(path)  # the recorder is still open
    assert early.n_samples == 5 and early.metadata["ndi_ids"] == [4, 7]
    np.testing.assert_array_equal(early.sensors["S4"][:, 0] * 1000, [1, 2, 3, 4, 5])
    assert np.isnan(early.sensors["S7"]).all()
    with open(path, "a", encoding="ascii") as f:  # a crash in the middle of a row
        f.write("0.050000\t6\t1102\t4\t55\t6.5")
    after_crash = read_ndi_wave(path)
    assert after_crash.n_samples == 5 and after_crash.metadata["truncated"]
    recorder.close()
    assert free_path(tmp_path, "live") == tmp_path / "live_2.tsv"
    with pytest.raises(FileExistsError):  # never overwrites a session
        TsvRecorder(path).write(LiveFrame(1, 0.0, 0.0, np.zeros((1, 3)), np.zeros((1, 4)), np.zeros(1)))


def test_ctrl_c_stops_cleanly_and_keeps_the_file(demo, tmp_path):
    from tonguevis.live.source import RecordingSource

    class Interrupted(RecordingSource):
        calls = 0

        def get(self, timeout=None):
            self.calls += 1
            if self.calls == 30:
                raise KeyboardInterrupt
            return super().get(timeout)

    source = Interrupted(demo, speed=20.0).start()
    result = record(source, tmp_path / "c.tsv")
    assert result.interrupted and result.frames >= 29 and source.finished
    rec = open_recording(result.path)
    assert rec.n_samples == result.frames and result.head_corrected.exists()
    assert_equals_stream(rec, demo)


def test_frames_with_another_slot_count_are_fitted_and_counted(tmp_path):
    recorder = TsvRecorder(tmp_path / "a.tsv")
    shapes = [2, 3, 1]
    for k, n in enumerate(shapes):
        recorder.write(LiveFrame(k + 1, 0.01 * k, 0.0, np.full((n, 3), 5.0), np.full((n, 4), 0.5), np.zeros(n)))
    recorder.close()
    rec = read_ndi_wave(tmp_path / "a.tsv")
    assert rec.sensor_names == ["S0", "S1"] and recorder.mismatched == 2
    assert np.isnan(rec.sensors["S1"][2]).all() and np.isfinite(rec.sensors["S1"][1]).all()


def test_a_repeated_or_older_frame_is_not_written(tmp_path):
    """Readers need increasing times: a frame repeated after a reconnection is counted, not written."""
    recorder = TsvRecorder(tmp_path / "t.tsv")
    empty = LiveFrame(0, 0.0, 0.0, np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0))
    assert recorder.write(empty) is False and recorder.empty == 1  # no sensors yet: no row, no header
    written = [recorder.write(LiveFrame(k, t, 0.0, np.full((1, 3), float(k)), np.full((1, 4), 0.5), np.zeros(1)))
               for k, t in enumerate([0.0, 0.01, 0.01, 0.005, 0.02], start=1)]
    recorder.close()
    assert written == [True, True, False, False, True] and recorder.out_of_order == 2
    rec = read_ndi_wave(tmp_path / "t.tsv")
    np.testing.assert_array_equal(rec.metadata["meas_id"], [1, 2, 5])


def test_head_correction_needs_three_references(tmp_path):
    rec = synthetic(n=20, names=("TT", "REF1", "REF2"))
    from tonguevis.io.ndi_wave import write_ndi_wave

    write_ndi_wave(rec, tmp_path / "x.tsv", sensor_map={"TT": 0, "REF1": 1, "REF2": 2})
    out, note = write_head_corrected(tmp_path / "x.tsv", {"TT": 0, "REF1": 1, "REF2": 2})
    assert out is None and "2 head reference(s) (REF1, REF2); 3 are needed" in note


def run_cli(argv, timeout=20.0):
    """tonguevis.cli.main(argv) in a thread (so a hang fails the test instead of blocking it): its exit status."""
    out = {}
    thread = threading.Thread(target=lambda: out.setdefault("status", main(argv)), daemon=True)
    thread.start()
    thread.join(timeout)
    assert not thread.is_alive(), f"tonguevis {' '.join(argv)} did not finish in {timeout} s"
    return out["status"]


def test_record_cli_end_to_end(demo, tmp_path, capsys):
    with ReplayServer(demo, speed=5.0) as server:
        status = run_cli(["record", "--source", f"127.0.0.1:{server.port}", "--out", str(tmp_path / "out"),
                          "--seconds", "0.5", "--name", "first", "--capture"])
    assert status == 0
    text = capsys.readouterr().out
    assert re.search(r"done: \d+ frames \(0\.\d s\) in .*first\.tsv", text), text
    assert "head-corrected (REF1, REF2, REF3)" in text
    rec = open_recording(tmp_path / "out" / "first.tsv")
    assert rec.sensor_names == demo.sensor_names and rec.n_samples > 50
    assert_equals_stream(rec, demo)
    # The raw bytes kept beside it hold the same frames.
    from tonguevis.live.rtc3d import read_capture

    _, frames = read_capture((tmp_path / "out" / "first.rtc3d").read_bytes())
    assert [f.frame for f in frames[:rec.n_samples]] == rec.metadata["meas_id"].astype(int).tolist()
    assert "raw bytes received:" in text
    # Another command opens it.
    assert main(["info", str(tmp_path / "out" / "first_headcorrected.tsv")]) == 0
    assert "sensors (8)" in capsys.readouterr().out


def test_stream_cli_serves_the_record_cli(tmp_path, capsys):
    short = synthetic(n=60)
    from tonguevis.io.ndi_wave import write_ndi_wave

    write_ndi_wave(short, tmp_path / "short.tsv")
    out = {}
    argv = ["stream", str(tmp_path / "short.tsv"), "--listen", "127.0.0.1:0", "--speed", "2"]
    thread = threading.Thread(target=lambda: out.setdefault("status", main(argv)), daemon=True)
    thread.start()
    port = None
    for _ in range(200):
        m = re.search(r"on 127\.0\.0\.1:(\d+)", capsys.readouterr().out)
        if m:
            port = int(m.group(1))
            break
        thread.join(0.02)
    assert port is not None, "tonguevis stream printed no address"
    status = run_cli(["record", "--source", f"127.0.0.1:{port}", "--out", str(tmp_path / "rec"), "--name", "s",
                      "--stall", "0.3", "--retries", "1", "--sensors", "paper"])
    thread.join(10)
    assert status == 0 and out["status"] == 0
    text = capsys.readouterr().out
    assert "60 frames" in text
    assert "1 head reference(s) (REF1); 3 are needed" in text
    # --sensors paper named the three slots recorded (its other names are left out of the map saved beside).
    rec = open_recording(tmp_path / "rec" / "s.tsv")
    assert rec.sensor_names == ["REF1", "TT", "TD"]
    assert json.loads((tmp_path / "rec" / "sensor_map.json").read_text())["sensors"] == {"REF1": 0, "TT": 1, "TD": 2}
    assert_equals_stream(rec, open_recording(tmp_path / "short.tsv"))


def test_record_cli_with_nothing_to_record(tmp_path):
    import socket

    sock = socket.create_server(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    # The command itself, as a shell or a script runs it: its exit status and its error line.
    done = subprocess.run([sys.executable, "-m", "tonguevis", "record", "--source", f"127.0.0.1:{port}",
                           "--out", str(tmp_path), "--retries", "0"], capture_output=True, text=True, timeout=60,
                          cwd=REPO_DIR, env=dict(os.environ, PYTHONPATH=str(REPO_DIR)))
    assert done.returncode == 2, (done.returncode, done.stdout, done.stderr)
    assert done.stderr.strip().splitlines()[-1].startswith(
        f"tonguevis record: error: nothing recorded: no frame arrived from 127.0.0.1:{port}")
    assert "nothing recorded" not in done.stdout
    assert list(tmp_path.iterdir()) == []
    assert main(["record", "--source", "localhost:notaport", "--out", str(tmp_path)]) == 2


def test_records_a_real_recording(tmp_path):
    path = SHARED / "ndi_wave" / "Example3.tsv"
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared third-party data is not here)")
    real = open_recording(path, {})
    with ReplayServer(real, speed=10.0) as server:
        source = WaveFrontSource("127.0.0.1", server.port).start()
        result = record(source, tmp_path / "real.tsv", seconds=0.5)
    back = open_recording(result.path, {})
    assert back.metadata["ndi_ids"] == real.metadata["ndi_ids"] and back.n_samples == real.n_samples
    assert_equals_stream(back, real)
    assert np.isnan(back.sensors["S2"]).all() and np.isfinite(back.sensors["S0"]).all()  # missing ports stay missing
    assert back.metadata["dropped_frames"] == real.metadata["dropped_frames"]  # the export's own gap, kept


def test_streams_and_records_a_recording_of_another_format(tmp_path):
    """Any recording tonguevis reads streams: a Haskins MVIEW file (its orientations are angles: no quaternions)."""
    path = SHARED / "mview" / "F01_B01_S01_R01_N.mat"
    if not path.exists():
        pytest.skip(f"{path} is absent (the shared third-party data is not here)")
    real = open_recording(path, audio=False)
    with ReplayServer(real, speed=10.0) as server:
        source = WaveFrontSource("127.0.0.1", server.port, stall_timeout=0.3, max_retries=0).start()
        result = record(source, tmp_path / "mview.tsv")
    back = open_recording(result.path)
    assert back.sensor_names == real.sensor_names and back.n_samples == real.n_samples
    assert_equals_stream(back, real)  # positions exact; quaternions NaN, as the stream had none
    assert all(np.isnan(q).all() for q in back.orientations.values())


def _stream_says(tmp_path, *options) -> str:
    """What `tonguevis stream` prints before its first client: its address, slots and notes."""
    short = tmp_path / "short.tsv"
    if not short.exists():
        from tonguevis.io.ndi_wave import write_ndi_wave

        write_ndi_wave(synthetic(n=60), short)
    process = subprocess.Popen([sys.executable, "-m", "tonguevis", "stream", str(short), *options],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=REPO_DIR,
                               env=dict(os.environ, PYTHONPATH=str(REPO_DIR)))
    lines = []
    try:
        while not lines or not lines[-1].startswith("sensor slots"):  # then the note, if any; then it waits
            line = process.stdout.readline()
            if not line:
                break
            lines.append(line)
        time.sleep(0.5)
    finally:
        process.terminate()
        rest = process.stdout.read()  # what readline() buffered too (communicate() reads past it)
        process.wait(timeout=30)
    return "".join(lines) + rest


def test_stream_on_a_loopback_address_does_not_say_other_machines_can_connect(tmp_path):
    """Issue 37: `stream --host 127.0.0.2` (this machine's loopback, as 127.0.0.1 is) said other machines could
    connect; listening on every network (0.0.0.0) still says so."""
    loopback = _stream_says(tmp_path, "--listen", "127.0.0.2:0")
    assert "streaming" in loopback and "on 127.0.0.2:" in loopback, loopback
    assert "other machines" not in loopback
    everywhere = _stream_says(tmp_path, "--listen", "0.0.0.0:0")
    assert "note: listening on 0.0.0.0: other machines that reach this one can connect" in everywhere, everywhere



def test_stream_listens_on_host_port_as_record_and_live_connect_to_it(tmp_path, capsys):
    """Issue 37: `stream` took --host/--port, `record` and `live` --source HOST:PORT. The address is one
    HOST:PORT everywhere (stream --listen); the old spellings still work, with a note."""
    old = _stream_says(tmp_path, "--host", "127.0.0.2", "--port", "0")
    assert "on 127.0.0.2:" in old and "--host is deprecated" in old and "--port is deprecated" in old, old
    assert "use --listen HOST:PORT" in old
    for argv in (["stream", str(DEMO_RECORDING), "--listen", "127.0.0.1:notaport"],
                 ["stream", str(DEMO_RECORDING), "--listen", ":3030"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--listen" in err[0] and "HOST:PORT" in err[0], err
