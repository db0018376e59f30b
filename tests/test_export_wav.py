"""tonguevis export-wav (issue 35): the sound and every sensor's x, y, z in one float32 WAV, read back by
SciPy and by Praat (``praat --run``) with the EMA within 0.05 mm."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from scipy.io import wavfile

from tests.conftest import shared_file
from tonguevis.cli import main
from tonguevis.paths import DATA_DIR

#: A Praat script printing, for each sample number given, every channel's value (tab-separated rows).
PRAAT_SCRIPT = """form Read back
  sentence wav x.wav
  sentence samples 1
endform
sound = Read from file: wav$
channels = Get number of channels
rate = Get sampling frequency
writeInfoLine: channels, tab$, rate
numbers$ = samples$ + " "
while length(numbers$) > 1
  space = index(numbers$, " ")
  n = number(left$(numbers$, space - 1))
  numbers$ = right$(numbers$, length(numbers$) - space)
  line$ = ""
  for c from 1 to channels
    v = Get value at sample number: c, n
    line$ = line$ + fixed$(v, 6) + tab$
  endfor
  appendInfoLine: line$
endwhile
"""


def _export(path, out, capsys=None):
    assert main(["export-wav", str(path), "--out", str(out)]) == 0
    rate, data = wavfile.read(out)
    sidecar = json.loads(out.with_suffix(".json").read_text())
    return rate, data, sidecar


def _ema_samples(recording, sidecar, rate, step: int = 7):
    """Every ``step``-th EMA sample inside the WAV: (WAV sample indices, {channel: value in mm})."""
    from tonguevis.preprocess.correction import head_corrected

    corrected = head_corrected(recording)
    k = np.round((corrected.times - sidecar["start_s"]) * rate).astype(int)
    keep = np.flatnonzero((k >= 0) & (k < sidecar["samples"]))[::step]
    expected = {}
    for channel in sidecar["channels"]:
        if channel.get("sensor"):
            expected[channel["name"]] = 1e3 * corrected.sensors[channel["sensor"]][keep, "xyz".index(channel["axis"])]
    return k[keep], expected, keep


def _check(recording, rate, data, sidecar, praat: bool, tmp_path):
    names = [c["name"] for c in sidecar["channels"]]
    assert data.dtype == np.float32 and data.shape == (sidecar["samples"], len(names)) and rate == sidecar["rate_hz"]
    samples, expected, keep = _ema_samples(recording, sidecar, rate)
    valid = {n: np.isfinite(v) for n, v in expected.items()}
    errors = [np.abs(data[samples, names.index(n)] - v)[valid[n]].max() for n, v in expected.items()]
    assert max(errors) < 0.05  # mm, half a sample of the sound from each EMA sample
    if not praat:
        return
    if shutil.which("praat") is None:
        pytest.skip("Praat is not installed (Debian: apt-get install praat): the Praat read-back is not checked")
    script = tmp_path / "read_back.praat"
    script.write_text(PRAAT_SCRIPT)
    wav = tmp_path / "ema.wav"
    chosen = samples[:: max(1, len(samples) // 40)]
    done = subprocess.run(["praat", "--run", str(script), str(wav), " ".join(str(int(k) + 1) for k in chosen)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.strip().splitlines()
    channels, praat_rate = lines[0].split("\t")
    assert int(channels) == len(names) and float(praat_rate) == rate
    values = np.array([[float(v) for v in line.split("\t") if v] for line in lines[1:]])
    assert values.shape == (len(chosen), len(names))
    assert np.abs(values - data[chosen]).max() < 1e-5  # Praat reads what SciPy reads (printed to 6 decimals)
    at = np.searchsorted(samples, chosen)
    for name, v in expected.items():
        ok = valid[name][at]
        assert np.abs(values[ok, names.index(name)] - v[at][ok]).max() < 0.05


def test_the_demo_with_its_sound(tmp_path):
    from tonguevis.workflows import open_recording

    path = DATA_DIR / "spk1_ta.tsv"
    if not path.exists():
        pytest.skip(f"demo corpus not built: {path}")
    rate, data, sidecar = _export(path, tmp_path / "ema.wav")
    recording = open_recording(path)
    sensors = recording.sensor_names
    assert [c["name"] for c in sidecar["channels"]] == ["sound"] + [f"{s}_{a}" for s in sensors for a in "xyz"]
    assert all(c["unit"] == "mm" and c["scale"] == 1.0 for c in sidecar["channels"][1:])
    assert rate == 16000 and sidecar["start_s"] == recording.audio.offset
    sound = recording.audio.samples
    assert np.array_equal(data[:len(sound), 0], sound)
    assert "head-corrected by REF1, REF2, REF3" in sidecar["frame"]
    _check(recording, rate, data, sidecar, praat=True, tmp_path=tmp_path)


@pytest.mark.parametrize("parts, sound", [(("ema", "mview", "F01_B01_S01_R01_N.mat"), True),
                                          (("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv"), False)])
def test_real_recordings_read_back_by_scipy_and_praat(parts, sound, tmp_path):
    from tonguevis.workflows import open_recording

    path = shared_file(*parts)
    rate, data, sidecar = _export(path, tmp_path / "ema.wav")
    recording = open_recording(path)
    assert (sidecar["channels"][0]["name"] == "sound") == sound
    assert rate == (recording.audio.rate if sound else 16000)
    _check(recording, rate, data, sidecar, praat=True, tmp_path=tmp_path)


def test_gaps_are_filled_and_listed(tmp_path):
    from tonguevis.io import Recording, write_recording

    times = np.arange(200) / 100.0
    tip = np.column_stack([np.sin(times), np.cos(times), times]) * 0.01
    dorsum = tip + 0.02
    tip[50:60] = np.nan
    recording = Recording(rate=100.0, times=times, sensors={"TT": tip, "TD": dorsum})
    write_recording(recording, tmp_path / "r.csv")
    rate, data, sidecar = _export(tmp_path / "r.csv", tmp_path / "ema.wav")
    assert list(sidecar["gaps_filled"]) == ["TT"] and sidecar["gaps_filled"]["TT"] == [[0.5, pytest.approx(0.59)]]
    k = int(0.55 * rate)
    expected = 1e3 * (tip[49, 2] + (tip[60, 2] - tip[49, 2]) * (0.55 - 0.49) / 0.11)  # the gap bridged linearly
    assert data[k, 2] == pytest.approx(expected, abs=1e-3)
    assert np.isfinite(data).all()


def test_a_wav_must_be_named_wav(tmp_path, capsys):
    path = DATA_DIR / "spk1_ta.tsv"
    assert main(["export-wav", str(path), "--out", str(tmp_path / "ema.flac")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "name it OUT.wav" in err and not (tmp_path / "ema.flac").exists()


def test_the_export_table_writes_it_from_a_session(tmp_path):
    from tonguevis.workflows.exports import write_export
    from tonguevis.workflows.session import load_session

    path = DATA_DIR / "spk1_ta.tsv"
    if not path.exists():
        pytest.skip(f"demo corpus not built: {path}")
    written = write_export("wav", load_session(path), tmp_path / "session.wav")
    assert written == tmp_path / "session.wav" and (tmp_path / "session.json").is_file()
    assert wavfile.read(written)[1].shape[1] == 1 + 3 * 8
