"""The production finder against the hand labels of real clinic recordings (../shared).

Opti-Speech sessions of isolated /ka/ and /ta/ repetitions, labelled by fixed rules and checked
by eye (``NAME.labels.TextGrid``; ``ambiguous`` stretches count neither way).  The same settings
serve every file: nothing here is tuned to one of them.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import SHARED_DATA
from tonguevis.analysis.production_scores import labelled_recordings, score_against_labels
from tonguevis.workflows import find_recording_productions, open_recording

FOLDER = SHARED_DATA / "ema" / "optispeech"
LABELLED = labelled_recordings(FOLDER)
NAMES = [path.name for path, _ in LABELLED] or ["(none)"]


def _pair(name):
    pairs = dict((path.name, (path, labels)) for path, labels in LABELLED)
    if name not in pairs:
        pytest.skip(f"hand-labelled recordings not available in {FOLDER} (needs ../shared beside the repo)")
    return pairs[name]


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("told", ["file name", "data only"])
def test_one_production_per_labelled_syllable_within_60_ms(name, told):
    path, labels = _pair(name)
    rec = open_recording(path)
    if told == "data only":  # no syllable in the name: the articulator comes from the motion
        rec.metadata["file"] = str(path.with_name("session.tsv"))
    table = find_recording_productions(rec, keep=None)
    score = score_against_labels(table, labels)
    assert score["labelled"] > 0
    assert score["found"] == score["labelled"] == score["matched"], score
    assert score["median_error_ms"] <= 30.0 and score["max_error_ms"] <= 60.0, score
    assert table.articulator == ("TD" if "Kah" in name else "TT")


def test_the_paper_rule_does_not_thin_isolated_repetitions():
    path, labels = _pair("006_OSN12_Kah_nofb_natural_take2_HR.tsv")
    table = find_recording_productions(open_recording(path))  # default: the paper's 2nd-4th of trains
    assert len(table) == 10 and all(n == 1 for n in table.counts)
    assert any("no trains" in note for note in table.notes)


def test_clear_and_unclear_sessions_are_told_apart():
    """006 and 007: every syllable certain; 009: most of it ambiguous to the labeller."""
    clear = {name: find_recording_productions(open_recording(_pair(name)[0]), keep=None).clear
             for name in ("006_OSN12_Kah_nofb_natural_take2_HR.tsv", "007_OSN12_Kah_withFb_natural_HR.tsv",
                          "009_OSN12_Tah_withFb_natural_HR.tsv")}
    assert clear == {"006_OSN12_Kah_nofb_natural_take2_HR.tsv": True, "007_OSN12_Kah_withFb_natural_HR.tsv": True,
                     "009_OSN12_Tah_withFb_natural_HR.tsv": False}


def test_landmarks_on_real_ka_are_ordered_and_the_closure_near_the_label():
    from tonguevis.io.textgrid import read_textgrid

    path, labels = _pair("007_OSN12_Kah_withFb_natural_HR.tsv")
    table = find_recording_productions(open_recording(path), keep=None)
    closures = sorted(lab.start for lab in read_textgrid(labels) if lab.tier == "closure")
    found = [m.times["maxc"] for m in table.landmarks]
    np.testing.assert_allclose(found, closures, atol=0.06)
    for m in table.landmarks:
        t = m.times
        assert t["gons"] <= t["pvel"] <= t["nons"] <= t["maxc"] <= t["noffs"] <= t["pvel2"] <= t["goffs"]
        assert t["goffs"] <= t["vowel"] + 0.3
        assert 0.02 < m.peak_velocity < 1.0 and 0.02 < m.peak_velocity2 < 1.0  # 20 mm/s .. 1 m/s


def test_ka_energy_curves_are_one_family():
    """Each /ka/ once: the energy curves of a session share one shape (they were two opposite
    shapes when every /ka/ was cut in two)."""
    from tonguevis.analysis.energy import production_curves
    from tonguevis.workflows import simulate_recording

    path, _ = _pair("006_OSN12_Kah_nofb_natural_take2_HR.tsv")
    rec = open_recording(path)
    table = find_recording_productions(rec, keep=None)
    curves = production_curves(simulate_recording(rec, modes=40), table, recording=path.stem)
    grid = np.linspace(0, 1, 50)
    shapes = np.array([np.interp(grid, c.time_norm, c.energy) for c in curves])
    typical = np.median(shapes, axis=0)
    agreement = np.array([np.corrcoef(s, typical)[0, 1] for s in shapes])
    assert len(curves) == 10 and np.median(agreement) > 0.9 and agreement.min() > 0.5, agreement
