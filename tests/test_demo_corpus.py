"""The committed SYNTHETIC demo corpus (data/): readable, segmentable to its truth, reproducible."""

import importlib.util
import json

import numpy as np
import pytest

from tonguevis.io import read_recording
from tonguevis.paths import DATA_DIR, REPO_DIR
from tonguevis.preprocess import (
    correct_head, correct_jaw, find_productions, find_rest_interval, find_trains, rest_pose,
)

TRUTH_PATH = DATA_DIR / "demo_truth.json"
SENSOR_MAP = DATA_DIR / "sensor_map.json"
FRAME = 0.01  # seconds per sample at 100 Hz


@pytest.fixture(scope="module")
def truth():
    return json.loads(TRUTH_PATH.read_text())


def load(name):
    return read_recording(DATA_DIR / name, sensor_map=SENSOR_MAP)


def generator():
    spec = importlib.util.spec_from_file_location("make_demo_data", REPO_DIR / "scripts" / "make_demo_data.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_corpus_is_complete_and_says_synthetic(truth):
    assert truth["synthetic"] is True and "SYNTHETIC" in truth["note"]
    expected = {f"{s}_{c}.tsv" for s in ("spk1", "spk2", "spk3") for c in ("ta", "ka", "la", "ra")}
    assert set(truth["files"]) == expected
    for name in expected:
        assert (DATA_DIR / name).exists() and (DATA_DIR / name).with_suffix(".wav").exists()
    total = sum(p.stat().st_size for p in DATA_DIR.iterdir())
    assert total < 25e6


def test_sensor_map_is_the_paper_preset():
    ours = json.loads(SENSOR_MAP.read_text())["sensors"]
    preset = json.loads((REPO_DIR / "tonguevis" / "presets" / "paper.json").read_text())["sensors"]
    assert ours == preset


@pytest.mark.parametrize("name", [f"{s}_{c}.tsv" for s in ("spk1", "spk2", "spk3") for c in ("ta", "ka", "la", "ra")])
def test_segmentation_finds_every_true_production(name, truth):
    rec = correct_head(load(name))
    table = find_productions(rec, keep=None)
    true = truth["files"][name]["productions"]
    assert len(table) == len(true) == 25
    found = table.as_array()
    expected = np.array([[p["train"], p["index"], p["start"], p["end"], p["release"], p["vowel"]] for p in true])
    np.testing.assert_array_equal(found[:, :2], expected[:, :2])
    # boundaries (start = release, end) within 3 frames; the vowel too
    assert np.max(np.abs(found[:, 2:] - expected[:, 2:])) <= 3 * FRAME
    # the recording as stored (head motion included) segments as well
    raw = find_productions(load(name), keep=None).as_array()
    assert raw.shape == found.shape and np.max(np.abs(raw[:, 2:4] - expected[:, 2:4])) <= 3 * FRAME


def test_default_keeps_productions_two_to_four(truth):
    table = find_productions(load("spk1_ta.tsv"))
    assert [(p.train, p.index) for p in table] == [(t, i) for t in range(1, 6) for i in (2, 3, 4)]


def test_trains_and_rest(truth):
    name = "spk3_ra.tsv"
    rec = load(name)
    trains = find_trains(rec)
    expected = truth["files"][name]["trains_s"]
    assert len(trains) == len(expected) == 5
    np.testing.assert_allclose(trains, expected, atol=3 * FRAME)
    kinematic = find_trains(rec.with_sensors(rec.sensors, audio=None))
    assert len(kinematic) == 5
    start, end = find_rest_interval(rec)
    assert start <= 0.1 and 4.7 <= end <= 5.05  # the 5 s rest


def test_speaker_habits():
    """spk2's /k/ dorsum peak is weaker than spk1's; spk3's left lateral moves more than its right."""
    def rise(name, sensor):
        rec = correct_jaw(correct_head(load(name)))
        pose = rest_pose(rec, find_rest_interval(rec))
        return np.nanpercentile(rec.sensors[sensor][:, 2], 99.5) - pose[sensor][2]

    assert rise("spk1_ka.tsv", "TD") > 0.008 and rise("spk2_ka.tsv", "TD") < 0.7 * rise("spk1_ka.tsv", "TD")

    rec = correct_jaw(correct_head(load("spk3_ta.tsv")))
    spread = {s: np.ptp(rec.sensors[s][500:, 2]) for s in ("TL", "TR")}
    assert spread["TL"] > 1.5 * spread["TR"]


def test_files_are_what_the_script_makes(truth):
    """Regenerating one file in memory reproduces the committed positions, audio and truth."""
    make = generator()
    rec, file_truth = make.synthesize("spk2", "la")
    stored = read_recording(DATA_DIR / "spk2_la.tsv", sensor_map={})  # the raw S<Id> channels
    assert stored.sensor_names == list(rec.sensors)
    for name in rec.sensors:
        np.testing.assert_allclose(stored.sensors[name], rec.sensors[name], atol=1.5e-9)  # 6 decimals of mm
    np.testing.assert_allclose(stored.audio.samples, rec.audio.samples, atol=1.0 / 32767)
    assert file_truth == truth["files"]["spk2_la.tsv"]


def test_corrections_recover_the_generated_tongue_motion():
    """Head then jaw correction of a demo file leaves the generator's tongue-on-jaw motion plus noise."""
    make = generator()
    rec, _ = make.synthesize("spk1", "ta")
    rec = rec.renamed({f"S{i}": name for name, i in make.NDI_IDS.items()})
    rng = np.random.default_rng(make.file_seed("spk1", "ta"))
    trains, _ = make.schedule("spk1", "ta", rng)
    events = make.articulator_events("spk1", "ta", trains, rng)
    head_mm, _ = make.head_frame_motion("spk1", events, rec.times)
    jaw_mm = head_mm["JAW"] - make.BASE_LAYOUT["JAW"]
    assert 0.005 <= np.ptp(jaw_mm[:, 2]) / 1000 <= 0.010  # the jaw opens 5-10 mm
    interval = find_rest_interval(rec)
    corrected = correct_jaw(correct_head(rec, rest_interval=interval), rest_interval=interval)
    # The head frame of the correction is the head pose during rest: fit that one rigid transform.
    from tonguevis.preprocess import fit_similarity

    refs = ["REF1", "REF2", "REF3"]
    g = fit_similarity(np.array([head_mm[r][0] for r in refs]) / 1000,
                       np.array([np.nanmean(corrected.sensors[r], axis=0) for r in refs]))
    for name in ("TT", "TD", "TL", "TR"):
        expected = g.apply((head_mm[name] - jaw_mm) / 1000)  # tongue relative to the jaw
        error = np.linalg.norm(corrected.sensors[name] - expected, axis=1)
        # sensor and jaw noise alone give 0.37 mm; without head correction it is 0.77 mm
        assert np.sqrt(np.mean(error**2)) < 0.0005
