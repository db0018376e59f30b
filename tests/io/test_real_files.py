"""Readers against the real third-party files of ../shared/data/ema (skipped when absent)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file
from tests.io.test_readers_common import check_recording
from tonguevis.io import RecordingError, read_recording, write_recording


def test_carstens_ag501_matches_artk_conversion():
    rec = read_recording(shared_file("ema", "carstens", "artk_ag501.pos"))
    check_recording(rec, n_expected=10)
    assert rec.metadata["carstens_kind"] == "AG50x V002"
    assert rec.rate == 250.0
    assert rec.sensor_names == [f"CH{i}" for i in range(1, 17)]
    txt = shared_file("ema", "carstens", "artk_ag501.txt")
    header = txt.read_text().splitlines()[0].split("\t")
    table = np.loadtxt(txt, skiprows=1, delimiter="\t")
    assert table.shape == (10, 16 * 7)
    for ch in range(1, 17):
        cols = [header.index(f"Ch{ch}_{a}") for a in ("X", "Y", "Z")]
        np.testing.assert_allclose(rec.sensors[f"CH{ch}"], table[:, cols] / 1000.0, atol=5e-6)
        angle_cols = [header.index(f"Ch{ch}_{a}") for a in ("phi", "theta")]
        np.testing.assert_allclose(rec.orientations[f"CH{ch}"], table[:, angle_cols], atol=5e-3)
        np.testing.assert_allclose(rec.metadata["rms"][:, ch - 1], table[:, header.index(f"Ch{ch}_RMS")], atol=5e-3)


def test_carstens_ag501_bvh_by_artk_matches_the_pos_file():
    pos = read_recording(shared_file("ema", "carstens", "artk_ag501.pos"))
    bvh = read_recording(shared_file("ema", "carstens", "artk_ag501.bvh"))
    check_recording(bvh, n_expected=10)
    assert bvh.rate == pytest.approx(250.0)
    for ch in range(1, 17):
        np.testing.assert_allclose(bvh.sensors[f"Ch{ch}"], pos.sensors[f"CH{ch}"], atol=1e-9)
        # artk puts phi and theta into the first two rotation channels
        np.testing.assert_allclose(bvh.orientations[f"Ch{ch}"][:, :2], pos.orientations[f"CH{ch}"], atol=1e-4)


def test_carstens_ag500_headerless_defaults_to_12_channels(caplog, tmp_path):
    path = shared_file("ema", "carstens", "artk_ag500.pos")
    rec = read_recording(path)
    check_recording(rec, n_expected=10)
    assert rec.metadata["carstens_kind"] == "AG500 headerless"
    assert len(rec.sensors) == 12 and rec.rate == 200.0
    np.testing.assert_allclose(rec.sensors["CH1"][0], [0.001, 0.002, 0.003])  # values 1, 2, 3 mm
    np.testing.assert_allclose(rec.sensors["CH2"][0], [0.008, 0.009, 0.010])
    assert read_recording(path, channels=8).n_samples == 15  # an explicit count wins
    # with an explicit count a partial last frame is dropped with a warning (3360 = 17 * 196 + 28)
    assert read_recording(path, channels=7).n_samples == 17
    assert "partial last frame" in caplog.text
    # without a count, a size that is no whole number of 12-channel frames asks for channels=
    cut = tmp_path / "cut.pos"
    cut.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(RecordingError, match="pass channels="):
        read_recording(cut)
    assert read_recording(cut, channels=12).n_samples == 9


def test_rticulate_ag500_is_anatomically_plausible():
    rec = read_recording(shared_file("ema", "carstens", "rticulate_0025.pos"), sensor_map={
        "TBK": 3, "TB": 4, "TT": 5, "REF1": 6, "JAW": 7})
    check_recording(rec, n_expected=20)
    assert rec.rate == 200.0 and rec.duration == pytest.approx(0.1)
    ears = np.linalg.norm(np.nanmean(rec.sensors["CH1"] - rec.sensors["CH2"], axis=0))
    assert 0.10 < ears < 0.18  # right to left ear in metres
    tongue = np.linalg.norm(np.nanmean(rec.sensors["TT"] - rec.sensors["TBK"], axis=0))
    assert 0.01 < tongue < 0.08  # tip to back


def test_est_track_ascii_equals_binary():
    ascii_rec = read_recording(shared_file("ema", "est_track", "artk_esttrack.txt"))
    binary = read_recording(shared_file("ema", "est_track", "artk_esttrack.bin"))
    for rec in (ascii_rec, binary):
        check_recording(rec, n_expected=10)
        assert rec.metadata["format"] == "est_track"
        assert rec.sensor_names == [f"Ch{i}" for i in range(1, 13)]
        assert rec.rate == pytest.approx(200.0)
    assert ascii_rec.metadata["est_data_type"] == "ascii" and binary.metadata["est_data_type"] == "binary"
    np.testing.assert_allclose(ascii_rec.times, binary.times, atol=1e-6)
    for name in ascii_rec.sensor_names:
        np.testing.assert_allclose(ascii_rec.sensors[name], binary.sensors[name], atol=1e-9)
        np.testing.assert_allclose(ascii_rec.orientations[name], binary.orientations[name], atol=1e-5)
    for key, series in ascii_rec.metadata["extra_channels"].items():
        np.testing.assert_allclose(series, binary.metadata["extra_channels"][key], atol=1e-5)
    np.testing.assert_allclose(ascii_rec.sensors["Ch1"][0], [0.001, 0.002, 0.003])
    np.testing.assert_allclose(ascii_rec.sensors["Ch12"][-1], np.array([834, 835, 836]) / 1000.0)
    # the coil number names the channel in a sensor map
    mapped = read_recording(shared_file("ema", "est_track", "artk_esttrack.bin"), sensor_map={"TT": 3})
    np.testing.assert_allclose(mapped.sensors["TT"], binary.sensors["Ch3"])


def test_mview_haskins_labels_audio_and_frame():
    rec = read_recording(shared_file("ema", "mview", "F01_B01_S01_R01_N.mat"), sensor_map="haskins")
    check_recording(rec, n_expected=262)
    assert rec.rate == 100.0
    assert rec.sensor_names == ["TBK", "TB", "TT", "UL", "LL", "ML", "JAW", "JAWL"]  # TR -> TBK
    assert rec.audio.rate == 44100.0 and rec.audio.duration == pytest.approx(2.605, abs=0.001)
    assert rec.metadata["sentence"] == "The birch canoe slid on the smooth planks."
    words = [lab.text for lab in rec.labels if lab.tier == "words"]
    phones = [lab for lab in rec.labels if lab.tier == "phones"]
    assert words[:4] == ["sp", "THE", "BIRCH", "CANOE"] and "PLANKS" in words
    assert len(phones) == 29 and phones[1].text == "DH"
    for lab in rec.labels:
        assert 0 <= lab.start <= lab.end <= rec.audio.duration + 1e-6
    # head-corrected Haskins frame = ours: tip in front of the rear, upper lip above the lower
    x = lambda name: np.nanmean(rec.sensors[name][:, 0])  # noqa: E731
    z = lambda name: np.nanmean(rec.sensors[name][:, 2])  # noqa: E731
    assert x("TT") > x("TB") > x("TBK")
    assert z("UL") > z("LL")
    assert rec.orientations["TT"].shape == (262, 3)
    # positions are metres: the tongue spans a few centimetres
    assert 0.01 < np.linalg.norm(np.nanmean(rec.sensors["TT"] - rec.sensors["TBK"], axis=0)) < 0.08


def test_real_mview_round_trips_through_bvh_csv_and_ndi(tmp_path):
    rec = read_recording(shared_file("ema", "mview", "F01_B01_S01_R01_N.mat"))
    ids = {name: i for i, name in enumerate(rec.sensor_names)}
    targets = {"take.bvh": {}, "take.csv": {}, "take_long.csv": {"layout": "long"}, "take.tsv": {"sensor_map": ids}}
    for name, options in targets.items():
        write_recording(rec, tmp_path / name, **options)
        back = read_recording(tmp_path / name, sensor_map=options.get("sensor_map"))
        check_recording(back, n_expected=rec.n_samples)
        assert back.sensor_names == rec.sensor_names
        np.testing.assert_allclose(back.times - back.times[0], rec.times - rec.times[0], atol=1e-6)
        for sensor in rec.sensor_names:
            np.testing.assert_allclose(back.sensors[sensor], rec.sensors[sensor], atol=1e-9, err_msg=name)
    # NDI Wave: the sensors are S<Id> without the map; the audio goes to the paired WAV
    ndi = read_recording(tmp_path / "take.tsv")
    assert ndi.sensor_names == [f"S{i}" for i in range(len(ids))]
    assert ndi.audio.rate == 44100.0
    np.testing.assert_allclose(ndi.audio.samples, rec.audio.samples, atol=1.0 / 32767 + 1e-9)


def test_real_ndi_round_trips_through_bvh_with_dropped_frame(tmp_path):
    rec = read_recording(shared_file("ema", "ndi_wave", "Example3.tsv"))
    write_recording(rec, tmp_path / "x.bvh")
    back = read_recording(tmp_path / "x.bvh", rotations="quaternion")
    # BVH frames are uniform: the dropped frame comes back as one NaN frame
    assert back.n_samples == rec.n_samples + 1
    gap = int(np.argmax(np.diff(rec.times))) + 1
    kept = np.r_[0:gap, gap + 1:back.n_samples]
    assert not back.valid("S0")[gap] and back.valid("S0")[kept].all()
    for name in rec.sensor_names:
        np.testing.assert_allclose(back.sensors[name][kept], rec.sensors[name], atol=1e-9)
        q_in, q_out = rec.orientations[name], back.orientations[name][kept]
        ok = np.all(np.isfinite(q_in), axis=1)
        # the same rotation: q and -q agree, so compare |<q_in, q_out>| with 1
        dots = np.abs(np.sum(q_in[ok] * q_out[ok], axis=1))
        np.testing.assert_allclose(dots, 1.0, atol=1e-5)
