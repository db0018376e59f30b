"""Opti-Speech sweep exports: clock, axes, channels; the real files of ../shared when present."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file
from tests.io.test_readers_common import check_recording
from tonguevis.io import RecordingError, read_recording
from tonguevis.io.optispeech import AXES_UNITY

HEADER = ["timestamp"] + ["Marker Number", "Qw", "Qx", "Qy", "Qz", "X", "Y", "Z"] * 2


def _write(path, times_ms, tt_unity, td_unity, tt_quat=None):
    lines = ["\t".join(HEADER)]
    for k, t in enumerate(times_ms):
        q = tt_quat[k] if tt_quat is not None else (0, 0, 0, 0)
        row = [f"{t:g}", "3", *map(str, q), *(repr(float(v)) for v in tt_unity[k])]
        row += ["7", "0", "0", "0", "0", *(repr(float(v)) for v in td_unity[k])]
        lines.append("\t".join(row))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_irregular_clock_with_repeated_rows_is_resampled_onto_a_uniform_one(tmp_path):
    rng = np.random.default_rng(0)
    steps = rng.integers(12, 33, size=300).astype(float)  # 12-32 ms, as the real exports
    times = 9.0 + np.concatenate([[0.0], np.cumsum(steps)])
    signal = lambda t: np.stack([3 * np.sin(2 * np.pi * 1.3 * t), np.cos(2 * np.pi * 0.7 * t), 0 * t], 1)  # noqa: E731
    tt = signal(times / 1000)
    td = tt + [0.0, 0.0, -30.0]
    # Every fifth Unity frame saw no new sample: the row repeats the one before, 1 ms later.
    rep = np.arange(5, len(times), 5)
    times_all = np.sort(np.concatenate([times, times[rep] + 1.0]))
    order = np.searchsorted(times, times_all, side="right") - 1
    path = _write(tmp_path / "irregular.tsv", times_all, tt[order], td[order])
    rec = read_recording(path)
    check_recording(rec)
    assert rec.metadata["format"] == "optispeech" and rec.rate == 100.0
    res = rec.metadata["resampled"]
    assert res["rows"] == len(times_all) and res["distinct_samples"] == len(times)
    assert rec.times[0] == pytest.approx(times[0] / 1000) and rec.times[-1] <= times[-1] / 1000
    np.testing.assert_allclose(np.diff(rec.times), 0.01, atol=1e-12)
    # Unity (x right, y up, z forward) -> ours (x anterior, y left, z up), mm -> m.
    truth = 1e-3 * signal(rec.times) @ AXES_UNITY.T
    err = np.abs(rec.sensors["TT"] - truth)
    assert err.max() < 0.05e-3  # PCHIP of a smooth 1.3 Hz signal sampled every 12-32 ms
    # Not just a copy of the nearest sample: that would be off by up to 0.4 mm here.
    nearest = 1e-3 * signal(times[np.abs(times[None] / 1000 - rec.times[:, None]).argmin(1)] / 1000) @ AXES_UNITY.T
    assert np.abs(nearest - truth).max() > 5 * err.max()


def test_a_long_hole_between_samples_stays_missing(tmp_path):
    times = np.concatenate([np.arange(0, 500, 20), np.arange(900, 1400, 20)]).astype(float)
    tt = np.column_stack([times / 100, 0 * times, 0 * times])
    rec = read_recording(_write(tmp_path / "hole.tsv", times, tt, tt - [0, 0, 30]))
    hole = (rec.times > 0.48 + 1e-6) & (rec.times < 0.90 - 1e-6)  # between the last and next sample
    assert np.all(~rec.valid("TT")[hole]) and np.all(rec.valid("TT")[~hole])


def test_axes_and_quaternions_follow_the_left_handed_unity_frame(tmp_path):
    # A 90 degree turn about Unity's up axis, as a Unity quaternion (w, x, y, z).
    q_unity = np.array([np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4), 0.0])
    tt = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 10.5], [0.0, 0.0, 11.0]])  # 10 mm forward, moving on
    path = _write(tmp_path / "axes.tsv", [0, 10, 20], tt, tt + [5.0, 0.0, 0.0], tt_quat=[q_unity] * 3)
    rec = read_recording(path)
    np.testing.assert_allclose(rec.sensors["TT"][0], [0.010, 0.0, 0.0])  # forward = our +x (anterior)
    np.testing.assert_allclose(rec.sensors["TD"][0] - rec.sensors["TT"][0], [0.0, -0.005, 0.0])  # right = our -y

    # Unity rotates vectors by the matrix of q in its own coordinates; the same physical turn
    # must come out of our quaternion applied to the mapped vector: R(q') = A R(q) Aᵀ.
    q_ours = rec.orientations["TT"][0]
    for v_unity in np.eye(3):
        np.testing.assert_allclose(_rotate(q_ours, AXES_UNITY @ v_unity), AXES_UNITY @ _rotate(q_unity, v_unity),
                                   atol=1e-12)


def _rotate(q, v):
    """v rotated by the unit quaternion q = (w, x, y, z)."""
    w, u = q[0], q[1:]
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


def test_garbage_and_empty_files_are_clear_errors(tmp_path):
    empty = tmp_path / "empty.tsv"
    empty.write_text("\t".join(HEADER) + "\n")
    with pytest.raises(RecordingError, match="no data rows"):
        read_recording(empty)
    bad = tmp_path / "bad.tsv"
    bad.write_text("\t".join(HEADER) + "\n" + "\t".join(["0", "3", "0", "0", "0", "0", "1", "x", "3",
                                                            "7", "0", "0", "0", "0", "1", "2", "3"]) + "\n")
    with pytest.raises(RecordingError, match="'x' is not a number"):
        read_recording(bad)


@pytest.mark.parametrize("name, seconds, probe", [
    ("002_OSN12_Palate_MidSagital_HR.tsv", 6.7, True),
    ("004_OSN12_Palate_Scribble_HR.tsv", 21.5, True),
    ("006_OSN12_Kah_nofb_natural_take2_HR.tsv", 22.0, False),
    ("009_OSN12_Tah_withFb_natural_HR.tsv", 10.9, False),
])
def test_real_exports_read_with_the_paper_layout_and_our_axes(name, seconds, probe):
    rec = read_recording(shared_file("ema", "optispeech", name))
    check_recording(rec)
    assert rec.rate == 100.0 and rec.duration == pytest.approx(seconds, abs=0.1)
    expected = {"TT", "TB", "TR", "TL", "TD", "JAW"} | ({"PROBE"} if probe else set())
    assert set(rec.sensor_names) == expected  # placeholders and the garbage probe slot dropped
    mean = {n: np.nanmean(rec.sensors[n], axis=0) for n in rec.sensor_names}
    assert mean["TT"][0] > mean["TB"][0] > mean["TD"][0]  # tip most anterior, dorsum most posterior
    assert mean["TL"][1] > mean["TB"][1] > mean["TR"][1]  # left is +y
    assert mean["JAW"][2] < mean["TT"][2] - 0.05  # the jaw sensor reads far below the tongue
    for n in ("TT", "TB", "TR", "TL", "TD"):
        assert rec.valid_fraction(n) == 1.0
        step = np.linalg.norm(np.diff(rec.sensors[n], axis=0), axis=1)
        assert step.max() < 0.01  # no jumps: under 1 m/s (the fastest real step: 7 mm in 10 ms)


SENSOR_HEADER = (["timestamp", "Placeholder1", "Placeholder2"]
                 + ["Sensor", "Status", "X", "Y", "Z", "Qw", "Qx", "Qy", "Qz"] * 3 + ["Counter"])


def _sensor_row(t_ms, tt_file, td_file, slot10, counter):
    """One Sensor-layout row: TT (Id 4), TD (Id 5), the unused slot (Id 10), a counter; X, Y, Z as the file holds them."""
    row = [f"{t_ms:g}", "0", "0"]
    for sensor_id, xyz in ((4, tt_file), (5, td_file), (10, slot10)):
        row += [str(sensor_id), "55", *(repr(float(v)) for v in xyz), "1", "0", "0", "0"]
    return "\t".join(row + [str(counter)])


def test_rows_repeating_the_previous_timestamp_are_merged_not_a_crash(tmp_path, capsys):
    # The older Sensor layout: some rows repeat the previous row's timestamp, differing only in
    # the unused slot (huge garbage, or now and then a small number) and the trailing counter.
    times = 20.0 * np.arange(60)  # ms
    tt = np.column_stack([2 * np.sin(times / 200), 10 + 0 * times, 0 * times])  # the file's X, Y, Z
    lines, counter = ["\t".join(SENSOR_HEADER)], 0
    repeated = set(range(3, 60, 4))
    for k, t in enumerate(times):
        lines.append(_sensor_row(t, tt[k], tt[k] - [0, 30, 0], [3e28, -1e28, 2e28], counter))
        counter += 1
        if k in repeated:  # the same time again: the unused slot now reads a plausible number
            lines.append(_sensor_row(t, tt[k], tt[k] - [0, 30, 0], [1.0, 2.0, 3.0], counter))
            counter += 1
    path = tmp_path / "repeated_times.tsv"
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode("ascii"))

    rec = read_recording(path)
    check_recording(rec)
    res = rec.metadata["resampled"]
    assert res["rows"] == 60 + len(repeated) and res["repeated_time_rows_merged"] == len(repeated)
    assert res["distinct_samples"] == 60
    assert np.all(np.diff(rec.times) > 0) and rec.times[-1] == pytest.approx(times[-1] / 1000)
    # The file's X, Y, Z are Unity's y, z, x: Unity (x right, y up, z forward) -> ours.
    unity = tt[:, [2, 0, 1]]
    np.testing.assert_allclose(rec.sensors["TT"][::2], 1e-3 * unity @ AXES_UNITY.T, atol=1e-9)

    from tonguevis.cli import main
    assert main(["info", str(path)]) == 0
    assert f"{len(repeated)} repeating the previous row's timestamp, merged into it" in capsys.readouterr().out
