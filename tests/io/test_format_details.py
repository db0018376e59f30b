"""Format details beyond the shared test: byte orders, breaks, 2-D coils, joints, layouts, headers."""

from __future__ import annotations

import numpy as np
import pytest

from tests.io import examples
from tests.io.synthetic import make_recording
from tonguevis.io import RecordingError, read_recording, write_recording


def test_est_big_endian_breaks_and_mngu0_preset(tmp_path):
    coils, xyz, names, times, values = examples._est_values(6)
    flags = np.ones(6)
    flags[2] = 0  # a break: no data in frame 2
    frames = np.column_stack([times, flags, values]).astype(">f4")
    header = examples._est_header("binary", names, 6).replace("ByteOrder 01", "ByteOrder 10")
    path = tmp_path / "be.ema"
    path.write_bytes(header.encode() + frames.tobytes())
    rec = read_recording(path, sensor_map="mngu0")
    assert rec.sensor_names == ["TT", "TB", "TD", "JAW"]
    assert not rec.valid("TT")[2] and rec.valid("TT")[[0, 1, 3, 4, 5]].all()
    np.testing.assert_allclose(rec.sensors["TB"][0], xyz[0, 1].astype(np.float32) / 1000, rtol=1e-6)
    assert rec.orientations["TT"].shape == (6, 3)
    assert set(rec.metadata["extra_channels"]) == {f"{c}_rms" for c in coils}


def test_est_two_dimensional_coils_and_unit_option(tmp_path):
    names = ["ul_x", "ul_y", "tt_x", "tt_y"]
    rows = "".join(f"{0.002 * k:.3f} 1 {k} {2 * k} {3 * k} {4 * k}\n" for k in range(5))
    path = tmp_path / "mocha.ema"
    path.write_text(examples._est_header("ascii", names, 5) + rows)
    rec = read_recording(path, unit="cm")
    assert rec.metadata["two_dimensional"] == ["ul", "tt"]
    np.testing.assert_allclose(rec.sensors["tt"][3], [0.09, 0.12, 0.0])  # cm -> m, z = 0
    assert rec.rate == pytest.approx(500.0)
    with pytest.raises(RecordingError, match="unknown length unit"):
        read_recording(path, unit="inch")


@pytest.mark.parametrize("change, message", [
    (("NumChannels 4", "NumChannels 5"), "do not cover"),
    (("DataType ascii", "DataType packed"), "unknown DataType"),
    (("NumFrames 5", "NumFrames 3"), "header says NumFrames 3"),
    (("EST_File Track", "EST_File Wave"), "EST_File Track"),
])
def test_est_bad_headers(tmp_path, change, message):
    names = ["a_x", "a_y", "a_z", "b_x"]
    rows = "".join(f"{0.01 * k:.3f} 1 1 2 3 4\n" for k in range(5))
    path = tmp_path / "bad.ema"
    path.write_text((examples._est_header("ascii", names, 5) + rows).replace(*change))
    with pytest.raises(RecordingError, match=message):
        read_recording(path)


def test_carstens_header_checks(tmp_path):
    ex = examples.make_ag501(tmp_path)
    with pytest.raises(RecordingError, match="contradicts"):
        read_recording(ex.path, channels=5)
    data = ex.path.read_bytes()
    for old, new, message in [(b"V002", b"V004", "unknown AG50x version"),
                              (b"NumberOfChannels=4", b"NumberOfChannels=0", "impossible NumberOfChannels"),
                              (b"SamplingFrequencyHz=250", b"SamplingFrequencyHz=abc", "numeric")]:
        bad = tmp_path / "bad.pos"
        bad.write_bytes(data.replace(old, new))
        with pytest.raises(RecordingError, match=message):
            read_recording(bad)


def test_carstens_axes_option(tmp_path):
    ex = examples.make_ag501(tmp_path)
    rec = read_recording(ex.path, axes="-x,-y,z")
    np.testing.assert_allclose(rec.sensors["CH1"], ex.truth["CH1"] * [-1, -1, 1], atol=1e-9)
    assert rec.metadata["frame"] == "tonguevis"


def test_bvh_joints_are_ignored_and_rotations_modes(tmp_path):
    text = """HIERARCHY
ROOT TT
{
  OFFSET 1 2 3
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT child
  {
    OFFSET 0 0 1
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 0 1
    }
  }
}
ROOT still
{
  OFFSET 4 5 6
  End Site
  {
    OFFSET 0 1 0
  }
}
MOTION
Frames: 2
Frame Time: 0.01
1 2 3 90 0 0   5 5 5
4 5 6 0 90 0   5 5 5
"""
    path = tmp_path / "joints.bvh"
    path.write_text(text)
    raw = read_recording(path)
    assert raw.sensor_names == ["TT", "still"]
    np.testing.assert_allclose(raw.sensors["TT"], [[0.001, 0.002, 0.003], [0.004, 0.005, 0.006]])
    np.testing.assert_allclose(raw.sensors["still"], [[0.004, 0.005, 0.006]] * 2)  # OFFSET, no channels
    np.testing.assert_allclose(raw.orientations["TT"], [[90, 0, 0], [0, 90, 0]])
    assert raw.metadata["rotation_orders"] == {"TT": "ZXY"}
    quat = read_recording(path, rotations="quaternion")
    s = np.sqrt(0.5)
    np.testing.assert_allclose(quat.orientations["TT"], [[s, 0, 0, s], [s, s, 0, 0]], atol=1e-12)
    # raw rotations survive a write -> read round trip with their channel order
    write_recording(raw, tmp_path / "again.bvh")
    again = read_recording(tmp_path / "again.bvh")
    assert again.metadata["rotation_orders"] == {"TT": "ZXY"}
    np.testing.assert_allclose(again.orientations["TT"], raw.orientations["TT"])
    # a sensor map renames the per-sensor rotation order too, so it still round-trips
    mapped = read_recording(path, sensor_map={"TD": "TT"})
    assert mapped.metadata["rotation_orders"] == {"TD": "ZXY"}
    write_recording(mapped, tmp_path / "mapped.bvh")
    assert "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" in (tmp_path / "mapped.bvh").read_text()


def test_bvh_bad_input(tmp_path):
    good = "HIERARCHY\nROOT A\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\nMOTION\nFrames: 2\nFrame Time: 0.01\n1 2 3\n4 5 6\n"
    for old, new, message in [("Xposition", "Wposition", "unknown BVH channel"),
                              ("Frames: 2", "Frames: 1", "2 frames of data but 'Frames: 1'"),
                              ("Frame Time: 0.01", "Frame Time: 0", "impossible"),
                              ("MOTION", "MOTON", "no MOTION"),
                              ("4 5 6", "4 x 6", "'x' is not a number"),
                              ("{\n OFFSET", "{\n OFSET", "expected 'OFFSET'")]:
        path = tmp_path / "bad.bvh"
        path.write_text(good.replace(old, new))
        with pytest.raises(RecordingError, match=message):
            read_recording(path)


def test_bvh_writer_nan_and_three_channel_sensors(tmp_path):
    rec = make_recording(n=8, names=("TT", "TD"), audio_rate=None, orientation=False)
    rec.sensors["TD"][2] = np.nan
    write_recording(rec, tmp_path / "p.bvh")
    text = (tmp_path / "p.bvh").read_text()
    assert "CHANNELS 3 Xposition Yposition Zposition" in text and "rotation" not in text
    assert "\tnan\tnan\tnan" in text
    back = read_recording(tmp_path / "p.bvh")
    assert back.valid("TD").tolist() == [True, True, False] + [True] * 5


def test_csv_unit_rate_and_layout_errors(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("time,TT_x,TT_y,TT_z\n0,1,2,3\n0.01,4,5,6\n")
    with pytest.raises(RecordingError, match="unit"):
        read_recording(path)
    rec = read_recording(path, unit="cm")
    np.testing.assert_allclose(rec.sensors["TT"][1], [0.04, 0.05, 0.06])
    assert rec.rate == pytest.approx(100.0)
    path.write_text("# unit: mm\n# rate: 250\ntime;TT_x;TT_y;TT_z;note\n0;1;2;3;7\n0.004;;;;8\n")
    rec = read_recording(path)
    assert rec.rate == 250.0 and rec.valid("TT").tolist() == [True, False]
    np.testing.assert_allclose(rec.metadata["extra_channels"]["note"], [7, 8])
    for body, message in [("time,sensor,x,y,z\n0,TT,1,2,3\n0,TT,1,2,3\n", "twice at the same time"),
                          ("time,TT_x,TT_y\n0,1,2\n", "lacks some of the _x, _y, _z"),
                          ("time,TT_x,TT_y,TT_z\n0,1,2,3\n0,1,2,3\n", "does not increase"),
                          ("time,TT_x,TT_y,TT_z\n0,1,2,3\n0.01,1,2\n0.02,1,2,3\n", "line 4 has 3 fields")]:
        path.write_text("# unit: mm\n" + body)
        with pytest.raises(RecordingError, match=message):
            read_recording(path)


def test_csv_long_layout_with_missing_rows(tmp_path):
    path = tmp_path / "long.csv"
    path.write_text("# unit: m\ntime,sensor,x,y,z\n0,TT,1,2,3\n0,JAW,4,5,6\n0.01,TT,7,8,9\n")
    rec = read_recording(path)
    assert rec.sensor_names == ["TT", "JAW"]
    np.testing.assert_allclose(rec.sensors["TT"], [[1, 2, 3], [7, 8, 9]])
    assert rec.valid("JAW").tolist() == [True, False]


def test_ndi_single_row_uses_nominal_rate(tmp_path):
    rec = make_recording(n=1, names=("S0",), audio_rate=None, with_gaps=False)
    write_recording(rec, tmp_path / "one.tsv")
    back = read_recording(tmp_path / "one.tsv")
    assert back.n_samples == 1 and back.rate == 100.0
    assert read_recording(tmp_path / "one.tsv", rate=250).rate == 250.0


def test_mview_variable_option_and_non_mview_mat(tmp_path):
    import scipy.io

    ex = examples.make_mview_v5(tmp_path)
    assert read_recording(ex.path, variable="take1").sensor_names == ["TBK", "TB", "TT"]  # Haskins' TR: tongue rear
    with pytest.raises(RecordingError, match="no MVIEW struct variable 'other'.*take1"):
        read_recording(ex.path, variable="other")
    plain = tmp_path / "plain.mat"
    scipy.io.savemat(str(plain), {"x": np.eye(3)})
    with pytest.raises(RecordingError, match=r"no MVIEW struct array.*variables: x"):
        read_recording(plain)


@pytest.mark.parametrize("maker", [examples.make_mview_v5, examples.make_mview_v73])
def test_mview_labels_and_audio_both_versions(tmp_path, maker):
    rec = read_recording(maker(tmp_path).path)
    assert rec.metadata["mat_version"] == ("7.3" if maker is examples.make_mview_v73 else "5")
    assert [(lab.tier, lab.text) for lab in rec.labels] == [
        ("words", "sp"), ("words", "TA"), ("phones", "sp"), ("phones", "T"), ("phones", "AA1")]
    assert rec.labels[1].start == pytest.approx(0.05) and rec.labels[1].end == pytest.approx(0.18)
    assert rec.audio.rate == 8000 and len(rec.audio.samples) == 1600
    assert rec.metadata["sentence"] == "Ta."
    np.testing.assert_allclose(rec.orientations["TB"], 7.0)
    # an invalid position makes the sample's orientation invalid too
    assert np.isnan(rec.orientations["TT"][4]).all() and not rec.valid("TT")[4]
