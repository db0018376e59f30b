"""Sweeps: what was streamed is what is saved (float32 precision), in files every tonguevis command opens."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from tonguevis.cli import main
from tonguevis.io import read_recording
from tonguevis.live.profiles import Profile, load_profile
from tonguevis.live.sweeps import Sweep, SweepError, load_sweep_targets, open_sweep
from tonguevis.live.targets import OscillatingTarget, ReplayTarget, StaticTarget
from tonguevis.paths import DEMO_RECORDING
from tonguevis.preprocess.correction import head_corrected
from tonguevis.workflows import open_recording

NAMES = ["REF1", "REF2", "REF3", "TT", "TD"]
F32 = np.finfo(np.float32).eps
N = 120


def _stream(seed: int = 0):
    """A 1.2 s stream at 100 Hz on a device clock at 1234.5 s: a nodding head carrying a moving tongue.

    Positions (N, 5, 3) m as float32 values (what the Wave sends), quaternions (N, 5, 4), with gaps.
    """
    rng = np.random.default_rng(seed)
    times = np.round(1234.5 + np.arange(N) / 100.0, 6)
    head = np.array([[-0.085, 0.062, -0.018], [0.022, 0.0, 0.048], [-0.001, 0.0, 0.009]])
    tongue = np.array([[-0.019, 0.0, -0.010], [-0.039, 0.0, -0.005]])
    tongue = tongue + 0.004 * np.sin(2 * np.pi * 2 * (times - times[0]))[:, None, None] * [0, 0, 1]
    angle = 0.05 * np.sin(2 * np.pi * 0.7 * (times - times[0]))
    c, s = np.cos(angle), np.sin(angle)
    rot = np.zeros((N, 3, 3))
    rot[:, 0, 0], rot[:, 0, 2], rot[:, 1, 1], rot[:, 2, 0], rot[:, 2, 2] = c, s, 1, -s, c
    local = np.concatenate([np.broadcast_to(head, (N, 3, 3)), tongue], axis=1)
    positions = np.einsum("nij,nsj->nsi", rot, local) + [0.1, 0.02, 0.05]
    positions = positions.astype(np.float32).astype(float)
    positions[10:15, 3] = np.nan   # TT lost for 5 frames
    positions[30, 4] = np.nan      # TD for one
    positions[50, 0] = np.nan      # a head reference for one
    q = rng.normal(size=(N, 5, 4))
    q = (q / np.linalg.norm(q, axis=2, keepdims=True)).astype(np.float32).astype(float)
    q[np.isnan(positions[:, :, 0])] = np.nan
    return times, positions, q


def _read(path):
    return read_recording(path)


def test_saved_sweep_equals_the_streamed_samples(tmp_path):
    times, positions, q = _stream()
    target = StaticTarget([0.08, 0.02, 0.04], 0.004, sensor="TT")
    sweep = Sweep("ta x10", NAMES, targets=[target], number=3, rate=100.0)
    for i in range(N):  # one frame at a time, as it arrives
        acc = sweep.add(times[i], positions[i], quaternions=q[i], frame=1000 + i)
        assert acc.shape == (1,)
    assert sweep.n_samples == N and sweep.elapsed_s == pytest.approx(1.19)
    saved = sweep.save(tmp_path / "sweep")
    raw = _read(saved.files["raw"])
    assert raw.sensor_names == NAMES  # the sensor map beside the TSV gives the names back
    np.testing.assert_allclose(raw.times, times - times[0], rtol=0, atol=1e-9)
    assert raw.rate == pytest.approx(100.0)
    for i, name in enumerate(NAMES):
        sent, back = positions[:, i], raw.sensors[name]
        np.testing.assert_array_equal(np.isnan(back), np.isnan(sent))
        np.testing.assert_allclose(back, sent, rtol=F32, atol=1e-9)
        np.testing.assert_allclose(raw.orientations[name], q[:, i], rtol=F32, atol=1e-6)
    # The head-corrected file: the raw stream corrected as every tonguevis command corrects it.
    fixed = _read(saved.files["head_corrected"])
    rec = sweep.recording()
    expected = head_corrected(rec)
    assert expected is not rec and "offline" in saved.summary["head_correction"]
    assert np.nanmax(np.abs(fixed.sensors["TT"] - raw.sensors["TT"])) > 0.001  # the nodding head was taken out
    for name in NAMES:
        np.testing.assert_allclose(fixed.sensors[name], expected.sensors[name], rtol=F32, atol=1e-9)
    assert np.isnan(fixed.sensors["TT"][50]).all()  # a frame without its head reference has no head frame
    # Accuracy per sample, units in the header, missing samples empty.
    with open(saved.files["accuracy"], newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["time_s", "frame", "T1_distance_mm", "T1_accuracy_percent"]
    table = np.array([[float(x) if x else np.nan for x in row] for row in rows[1:]])
    assert table.shape == (N, 4)
    np.testing.assert_allclose(table[:, 0], times - times[0], atol=1e-9)
    np.testing.assert_array_equal(table[:, 1], 1000 + np.arange(N))
    np.testing.assert_allclose(table[:, 3], sweep.accuracy[:, 0], atol=1e-4)
    np.testing.assert_allclose(table[:, 2], sweep.distance[:, 0] * 1000, atol=1e-4)
    assert np.isnan(table[10:15, 3]).all() and np.isfinite(table[15:, 3]).all()
    # The accuracy really is the distance to the target, by Opti-Speech's rule.
    d = np.linalg.norm(positions[:, 3] - target.point, axis=1)
    np.testing.assert_allclose(sweep.accuracy[:, 0], np.clip((0.008 - d) / 0.004, 0, 1) * 100)
    summary = json.loads(saved.files["summary"].read_text())
    assert summary["number"] == 3 and summary["name"] == "ta x10" and summary["n_samples"] == N
    assert summary["missing_samples"] == {"REF1": 1, "REF2": 0, "REF3": 0, "TT": 5, "TD": 1}
    assert summary["accuracy"][0]["n_missing"] == 5 and summary["accuracy"][0]["n_samples"] == N - 5
    assert summary["accuracy"][0]["mean_percent"] == pytest.approx(np.nanmean(sweep.accuracy))
    assert summary["cycle"]["period_s"] is None and "cycles" not in saved.files  # a static target has no cycle
    assert [t.to_dict() for t in load_sweep_targets(saved.folder)] == [target.to_dict()]


def test_live_head_correction_and_offsets_are_what_is_scored_and_saved(tmp_path):
    times, positions, _ = _stream(1)
    corrected = positions - [0.1, 0.02, 0.05]
    offset = np.array([0.01, 0.0, 0.0])
    # A target exactly where the corrected, offset tip is in frame 0: 100 % there.
    target = StaticTarget(corrected[0, 3] + offset, 0.002, sensor="TT")
    sweep = Sweep("offset", NAMES, targets=[target], sensor_offsets={"TT": offset})
    acc = sweep.add(times, positions, corrected=corrected, quaternions=np.tile([1.0, 0, 0, 0], (N, 5, 1)))
    assert acc.shape == (N, 1) and acc[0, 0] == 100.0
    d = np.linalg.norm(corrected[:, 3] + offset - target.point, axis=1)
    np.testing.assert_allclose(acc[:, 0], np.clip((0.004 - d) / 0.002, 0, 1) * 100)
    saved = sweep.save(tmp_path)
    fixed = _read(saved.files["head_corrected"])
    for i, name in enumerate(NAMES):
        np.testing.assert_allclose(fixed.sensors[name], corrected[:, i], rtol=F32, atol=1e-9)
    # Quaternions are kept raw but not beside positions corrected live (they would not match them).
    assert all(np.isnan(q).all() for q in fixed.orientations.values())
    np.testing.assert_array_equal(_read(saved.files["raw"]).orientations["TT"][:10], [[1.0, 0, 0, 0]] * 10)
    assert saved.summary["head_correction"].startswith("live")
    assert "offsets" in saved.summary["scored_on"]


def test_per_cycle_figures_are_saved(tmp_path):
    """A still tip against a 2 Hz sine target swinging 2 r away: 100 (1 - 1/pi) % every cycle."""
    r = 0.003
    t = np.arange(1500) / 1000.0  # 1.5 s at 1 kHz: three cycles of 0.5 s
    positions = np.zeros((1500, 2, 3))
    positions[:, 1] = [0.01, 0.0, 0.0]
    positions[600:700, 0] = np.nan  # the tip lost for 0.1 s in the second cycle
    target = OscillatingTarget([0, 0, 0], [2 * r, 0, 0], 2.0, r, sensor="TT")
    sweep = Sweep("cycles", ["TT", "JAW"], targets=[target])
    sweep.add(t, positions)
    cycles = sweep.cycles()
    assert len(cycles) == 3 and all(c.complete for c in cycles)
    assert cycles[1].targets[0].n_missing == 100 and cycles[0].targets[0].n_missing == 0
    for c in (cycles[0], cycles[2]):
        assert c.targets[0].mean_percent == pytest.approx(100 * (1 - 1 / np.pi), abs=0.05)
    saved = sweep.save(tmp_path)
    with open(saved.files["cycles"], newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(row["cycle"]) for row in rows] == [1, 2, 3]
    assert float(rows[2]["mean_accuracy_percent"]) == pytest.approx(100 * (1 - 1 / np.pi), abs=0.05)
    assert rows[1]["n_missing"] == "100" and rows[1]["start_s"] == "0.500000"
    assert saved.summary["cycle"]["n_complete"] == 3


def test_sweeps_are_numbered_per_profile_and_listed_in_it(tmp_path):
    times, positions, _ = _stream(2)
    profile = Profile("pt1", targets=[StaticTarget([0.08, 0.02, 0.04], 0.004)],
                      sensor_map={"REF1": 0, "REF2": 6, "REF3": 7, "TT": 1, "TD": 2})
    first, second = Sweep("ta", NAMES, profile=profile), Sweep("ka", NAMES, profile=profile)
    assert first.number == second.number == 1  # provisional: both started before either was saved
    first.add(times[:50], positions[:50])
    second.add(times[50:], positions[50:])
    a = first.save(profiles_root=tmp_path)
    b = second.save(profiles_root=tmp_path)
    assert (a.record.number, b.record.number) == (1, 2)
    assert a.folder == tmp_path / "pt1" / "sweeps" / "001_ta" and b.folder.name == "002_ka"
    back = load_profile("pt1", tmp_path)
    assert [(s.number, s.name, s.folder, s.n_samples) for s in back.sweeps] == [
        (1, "ta", "sweeps/001_ta", 50), (2, "ka", "sweeps/002_ka", 70)]
    assert back.next_sweep_number() == 3
    assert a.summary["ndi_ids"] == profile.sensor_map  # the profile's slots are the files' NDI Ids
    assert _read(a.files["raw"]).metadata["ndi_ids"] == [0, 1, 2, 6, 7]
    with pytest.raises(SweepError, match="already saved"):
        first.save(a.folder, update_profile=False)
    assert first.number == 1 and len(load_profile("pt1", tmp_path).sweeps) == 2


def test_bad_samples_are_refused_clearly():
    times, positions, _ = _stream(3)
    sweep = Sweep("x", NAMES, stop_after_s=0.5)
    sweep.add(times[0], positions[0])
    assert not sweep.finished
    with pytest.raises(SweepError, match="increasing"):
        sweep.add(times[0], positions[0])
    with pytest.raises(SweepError, match="shape"):
        sweep.add(times[1], positions[1, :4])
    with pytest.raises(SweepError, match="every sample or with none"):
        sweep.add(times[1], positions[1], corrected=positions[1])
    sweep.add(times[1:60], positions[1:60])
    assert sweep.finished  # the automatic stop
    with pytest.raises(SweepError, match="TX"):
        Sweep("x", NAMES, targets=[StaticTarget([0, 0, 0], 0.004, sensor="TX")])
    with pytest.raises(SweepError, match="no samples"):
        Sweep("x", NAMES).save("/nonexistent/never")
    with pytest.raises(SweepError, match="before the sweep's start"):
        Sweep("x", NAMES, start_s=2000.0).add(times[0], positions[0])
    with pytest.raises(SweepError, match="distinct"):
        Sweep("x", ["TT", "TT"])


def test_a_sweep_of_the_demo_opens_in_every_command(tmp_path, capsys):
    demo = open_recording(DEMO_RECORDING)
    names = demo.sensor_names
    n = 300  # 3 s: enough for a rest and a few /ta/
    stream = np.stack([demo.sensors[name][:n] for name in names], axis=1)
    quats = np.stack([demo.orientations[name][:n] for name in names], axis=1) if demo.orientations else None
    tip_rest = np.nanmedian(demo.sensors["TT"][:n], axis=0)
    sweep = Sweep("demo ta", names, targets=[StaticTarget(tip_rest + [0, 0, 0.01], 0.004)], axes="x,y,z",
                  rate=demo.rate)
    sweep.add(demo.times[:n] + 50.0, stream, quaternions=quats)
    sweep.set_audio(demo.audio.samples[: int(3 * demo.audio.rate)], demo.audio.rate)
    saved = sweep.save(tmp_path / "sweep")
    assert saved.files["raw_audio"].is_file() and saved.files["head_corrected_audio"].is_file()
    for key in ("raw", "head_corrected"):
        back = open_recording(saved.files[key])
        assert back.sensor_names == names and back.metadata["frame"] == "tonguevis"
        assert back.audio is not None and back.audio.duration == pytest.approx(3.0)
        if key == "raw":
            for name in names:
                np.testing.assert_allclose(back.sensors[name], demo.sensors[name][:n], rtol=F32, atol=1e-9)
    assert main(["info", str(saved.files["raw"])]) == 0
    out = capsys.readouterr().out
    assert "300 (3.000 s" in out and "TT" in out
    assert main(["simulate", str(saved.files["head_corrected"]), "--quiet", "--modes", "20"]) == 0
    assert "max sensor residual" in capsys.readouterr().out


def test_slot_names_and_a_ghost_from_a_saved_sweep(tmp_path):
    """Sensors named by slot (S<n>) keep their Ids; a saved sweep replays as a ghost template."""
    times, positions, _ = _stream(4)
    names = ["S0", "S3", "S4", "S1", "S2"]
    sweep = Sweep("slots", names)
    sweep.add(times, positions)
    folder = sweep.save(tmp_path / "slots").folder
    rec = open_sweep(folder, corrected=False)
    assert sorted(rec.sensor_names) == sorted(names) and rec.metadata["ndi_ids"] == [0, 1, 2, 3, 4]
    np.testing.assert_allclose(rec.sensors["S1"], positions[:, 3], rtol=F32, atol=1e-9)
    ghost = ReplayTarget.from_recording(open_sweep(folder), "S1", 0.004, start_s=0.2, end_s=0.8)
    assert set(ghost.template) == set(names) and ghost.period == pytest.approx(0.6)
    with pytest.raises(SweepError, match="not a saved sweep"):
        open_sweep(tmp_path)


def test_frames_as_the_sources_give_them_in_mm(tmp_path):
    from types import SimpleNamespace

    times, positions, q = _stream(5)
    sweep = Sweep("frames", NAMES, targets=[StaticTarget([0.08, 0.02, 0.04], 0.004)])
    for i in range(N):
        frame = SimpleNamespace(frame=7 + i, timestamp_s=times[i],
                                positions=(positions[i] * 1000).astype(np.float32).astype(float), quaternions=q[i])
        sweep.add_frame(frame)
    np.testing.assert_allclose(sweep.raw, positions, rtol=4 * F32)  # mm in, metres kept
    back = open_sweep(sweep.save(tmp_path).folder, corrected=False)
    np.testing.assert_allclose(back.sensors["TT"], positions[:, 3], rtol=4 * F32, atol=1e-9)
    np.testing.assert_allclose(back.orientations["TD"], q[:, 4], atol=1e-6)
