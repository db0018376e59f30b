"""NDI Wave TSV: the real export's quirks, write -> read round trips, bad input."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from tests.conftest import shared_file
from tests.io.synthetic import make_recording
from tonguevis.io import RecordingError, read_recording, write_recording
from tonguevis.io.ndi_wave import read_ndi_wave


def quat_to_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def test_real_export_quirks():
    path = shared_file("ema", "ndi_wave", "Example3.tsv")
    rec = read_recording(path)
    assert rec.metadata["format"] == "ndi_wave"
    assert rec.n_samples == 100
    # Names come from the Id column (0, 2, 3 ... 15), not the header labels (1, 3, 4 ... 16).
    assert rec.sensor_names == ["S0"] + [f"S{i}" for i in range(2, 16)]
    assert rec.rate == pytest.approx(100.0, rel=0.01)
    # the one 0.02 s gap: one frame missing, reported with the time before it
    assert rec.metadata["dropped_frames"] == [(pytest.approx(0.9985), 1)]
    # status 119 with empty fields, and status 55 with empty fields: both NaN
    assert rec.valid_fraction("S2") == 0.0
    assert rec.valid_fraction("S6") == 0.0
    assert rec.valid_fraction("S0") == 1.0
    # metres: the file's first S0 X is 45.170494 mm
    assert rec.sensors["S0"][0, 0] == pytest.approx(0.045170494)
    assert rec.metadata["original_unit"] == "mm"
    q = rec.orientations["S0"]
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-4)
    assert rec.audio is None


def test_a_status_other_than_ok_makes_a_filled_sample_nan(tmp_path):
    """A bad-fit coil reports numbers with a status other than 55: a dropout, not a position."""
    status = {0: [55, 55, 56, 55, 0], 4: [55, 119, 55, 23, 55]}
    header = ["AudioTime[s]", "MeasId", "WavId"]
    for sensor_id in status:
        k = sensor_id + 1
        header += [f"Sensor {k} Id", f"Sensor {k} Status", "X[mm]", "Y[mm]", "Z[mm]", "Q0", "Qx", "Qy", "Qz"]
    lines, xyz_mm = ["\t".join(header)], {s: [] for s in status}
    for row in range(5):
        fields = [f"{0.01 * row:.6f}", f"{row + 1}.000000", f"{220 * row}.000000"]
        for sensor_id, codes in status.items():
            xyz = [10.0 * sensor_id + row + 0.25, -20.0 + row, 30.5 - 2 * row]
            xyz_mm[sensor_id].append(xyz)
            fields += [f"{sensor_id}.000000", f"{codes[row]}.000000"] + [f"{v:.6f}" for v in xyz]
            fields += ["0.500000", "0.500000", "0.500000", "0.500000"]
        lines.append("\t".join(fields))
    path = tmp_path / "status.tsv"
    path.write_text("\n".join(lines) + "\n")
    rec = read_recording(path)
    assert rec.sensor_names == ["S0", "S4"]
    for sensor_id, codes in status.items():
        name = f"S{sensor_id}"
        ok = np.array(codes) == 55
        positions, quats = rec.sensors[name], rec.orientations[name]
        assert np.all(np.isnan(positions[~ok])) and np.all(np.isnan(quats[~ok])), name
        np.testing.assert_allclose(positions[ok], np.array(xyz_mm[sensor_id])[ok] / 1000.0, rtol=0, atol=1e-12)
        np.testing.assert_allclose(quats[ok], 0.5, rtol=0, atol=1e-12)
        assert rec.valid(name).tolist() == ok.tolist()
    assert rec.metadata["ndi_status"].tolist() == [list(pair) for pair in zip(*status.values())]


def test_round_trip_with_audio(tmp_path):
    rec = make_recording()
    out = tmp_path / "take.tsv"
    write_recording(rec, out)
    assert (tmp_path / "take.wav").exists()
    back = read_recording(out, sensor_map="paper")
    assert back.sensor_names == ["REF1", "TT", "TD", "TL", "TR", "JAW"]  # Id order 0..5
    np.testing.assert_allclose(back.times, rec.times, atol=1e-6)
    assert back.rate == pytest.approx(rec.rate)
    for name in rec.sensor_names:
        np.testing.assert_allclose(back.sensors[name], rec.sensors[name], atol=1e-9, equal_nan=True)
        np.testing.assert_allclose(back.orientations[name], rec.orientations[name], atol=1e-6, equal_nan=True)
        assert np.array_equal(back.valid(name), rec.valid(name))
    assert back.valid("TD").sum() == rec.n_samples - 3
    assert back.audio.rate == rec.audio.rate
    np.testing.assert_allclose(back.audio.samples, rec.audio.samples, atol=1.0 / 32767)
    assert back.metadata["audio_file"].endswith("take.wav")
    # without the map the Ids show: the paper preset put TT on Id 1
    plain = read_recording(out, audio=False)
    assert plain.audio is None
    np.testing.assert_allclose(plain.sensors["S1"], rec.sensors["TT"], atol=1e-9)


def test_writer_keeps_ndi_ids_and_header_labels(tmp_path):
    rec = make_recording(names=("S0", "S7", "S12"), audio_rate=None)
    out = tmp_path / "ids.tsv"
    write_recording(rec, out)
    header = out.read_text().splitlines()[0].split("\t")
    assert [h for h in header if h.endswith(" Id")] == ["Sensor 1 Id", "Sensor 8 Id", "Sensor 13 Id"]
    assert read_recording(out).sensor_names == ["S0", "S7", "S12"]
    assert not (tmp_path / "ids.wav").exists()


def test_axes_option_rotates_positions_and_quaternions(tmp_path):
    rec = make_recording(names=("S0", "S1"), audio_rate=None, with_gaps=False)
    out = tmp_path / "a.tsv"
    write_recording(rec, out)
    device = read_recording(out)
    assert device.metadata["frame"] == "device"
    ours = read_recording(out, axes="-y,x,z")
    A = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    np.testing.assert_allclose(ours.sensors["S1"], device.sensors["S1"] @ A.T)
    for k in (0, 7):
        R_dev = quat_to_matrix(device.orientations["S1"][k])
        R_ours = quat_to_matrix(ours.orientations["S1"][k])
        np.testing.assert_allclose(R_ours, A @ R_dev @ A.T, atol=1e-9)
    # a mirror mapping (left-handed device axes) still gives a proper rotation A R Aᵀ
    mirror = read_recording(out, axes="x,-y,z")
    M = np.diag([1.0, -1, 1])
    R_m = quat_to_matrix(mirror.orientations["S1"][3])
    np.testing.assert_allclose(R_m, M @ quat_to_matrix(device.orientations["S1"][3]) @ M, atol=1e-9)
    with pytest.raises(RecordingError, match="axes"):
        read_recording(out, axes="x,x,z")


def test_explicit_audio_path_and_missing_audio(tmp_path):
    rec = make_recording(names=("S0",))
    write_recording(rec, tmp_path / "a.tsv")
    (tmp_path / "a.wav").rename(tmp_path / "other.wav")
    assert read_recording(tmp_path / "a.tsv").audio is None
    assert read_recording(tmp_path / "a.tsv", audio=tmp_path / "other.wav").audio.rate == 8000
    with pytest.raises(RecordingError, match="does not exist"):
        read_recording(tmp_path / "a.tsv", audio=tmp_path / "none.wav")


def _written(tmp_path, **kw):
    rec = make_recording(names=("S0", "S3"), audio_rate=None, **kw)
    out = tmp_path / "t.tsv"
    write_recording(rec, out)
    return rec, out


def test_truncated_last_line_is_dropped_with_warning(tmp_path, caplog):
    rec, out = _written(tmp_path)
    data = out.read_bytes()
    cut = data[: len(data) - 40]  # inside the last row
    out.write_bytes(cut)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        back = read_recording(out)
    assert back.n_samples == rec.n_samples - 1
    assert back.metadata["truncated"] is True
    assert "incomplete last line" in caplog.text
    np.testing.assert_allclose(back.sensors["S3"], rec.sensors["S3"][:-1], atol=1e-9, equal_nan=True)
    # a file ending exactly at a line end loses nothing and warns nothing
    full = data[: data.rstrip(b"\n").rfind(b"\n") + 1]
    out.write_bytes(full)
    assert read_recording(out).n_samples == rec.n_samples - 1


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda lines: lines[:1], "header only"),
        (lambda lines: [], "empty"),
        (lambda lines: lines[:3] + [lines[3][:20]] + lines[4:], "line 4 has"),
        (lambda lines: lines[:2] + [lines[2].replace("55.000000", "abc", 1)] + lines[3:], "line 3, column"),
        (lambda lines: lines[:2] + [lines[3], lines[2]] + lines[4:], "does not increase at line 4"),
        (lambda lines: [lines[0].replace("Sensor 1 Id", "Sensor 1 Xd")] + lines[1:], "outside a sensor block"),
        (lambda lines: [lines[0]] + [lines[1]] + [lines[2].replace("\t0.000000\t55", "\t9.000000\t55", 1)] + lines[3:], "Id column"),
    ],
)
def test_malformed_files_name_file_and_problem(tmp_path, mutate, message):
    _, out = _written(tmp_path)
    lines = out.read_text().splitlines()
    out.write_text("\n".join(mutate(lines)) + "\n")
    with pytest.raises(RecordingError, match=message) as info:
        read_ndi_wave(out) if message != "empty" else read_recording(out)
    assert str(out) in str(info.value)


def test_wrong_unit_and_garbage(tmp_path):
    _, out = _written(tmp_path)
    text = out.read_text().replace("X[mm]", "X[in]", 1).replace("Y[mm]", "Y[in]", 1).replace("Z[mm]", "Z[in]", 1)
    out.write_text(text)
    with pytest.raises(RecordingError, match="units"):
        read_recording(out)
    junk = tmp_path / "junk.tsv"
    junk.write_bytes(b"\x00\x01\x02garbage")
    with pytest.raises(RecordingError, match="junk.tsv"):
        read_recording(junk)
