"""``tonguevis simulate --palate P --epg OUT`` on real recordings (issue 36): the OSN12 /ta/ 009 and /ka/ 006
with the speaker's palate fitted from the traces 002-004, at the defaults.  Electrodes light at the hand-labelled
closures, the /t/ palatograms' centre of gravity lies in front of the /k/ ones, and the file holds every frame."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from tests.conftest import shared_file
from tonguevis.cli import main

textgrid = pytest.importorskip("praatio.textgrid")

OSN = ("ema", "optispeech")


def _palatograms(name: str, palate, tmp_path, capsys):
    recording = shared_file(*OSN, f"{name}.tsv")
    out = tmp_path / f"{name}.csv"
    assert main(["simulate", str(recording), "--palate", str(palate), "--epg", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    rows = list(csv.DictReader(open(out)))
    closures = [e.time for e in textgrid.openTextgrid(str(shared_file(*OSN, f"{name}.labels.TextGrid")), False)
                .getTier("closure").entries]
    return rows, closures, printed


def _at(rows, t: float, reach: float = 0.03) -> list[dict]:
    return [r for r in rows if abs(float(r["time_s"]) - t) <= reach + 1e-9]


def test_the_palatogram_lights_at_the_closures_t_in_front_of_k(osn12_palate, tmp_path, capsys):
    cogs = {}
    for name, sound in (("009_OSN12_Tah_withFb_natural_HR", "t"), ("006_OSN12_Kah_nofb_natural_take2_HR", "k")):
        rows, closures, printed = _palatograms(name, osn12_palate, tmp_path, capsys)
        assert f"the palatogram of {len(rows)} frames" in printed
        assert len(rows) > 1000 and list(rows[0])[1] == "r1c2" and len(rows[0]) == 1 + 62 + 4
        times = np.array([float(r["time_s"]) for r in rows])
        assert np.all(np.diff(times) > 0)
        lit = 0
        cog = []
        for t in closures:
            around = _at(rows, t)
            best = max(around, key=lambda r: float(r["percent_contact"]))
            if float(best["percent_contact"]) > 0:
                lit += 1
                cog.append(float(best["cog"]))
                # the indices in the row are those of its electrodes
                contacts = sum(int(best[k]) for k in best if k.startswith("r"))
                assert float(best["percent_contact"]) == pytest.approx(100 * contacts / 62, abs=1e-3)
        assert lit >= 0.8 * len(closures), (name, lit, len(closures))
        cogs[sound] = np.mean(cog)
        assert "centre of gravity" in printed  # each production's palatogram at its closure, said
    assert cogs["t"] > cogs["k"] + 0.5, cogs


def test_epg_without_a_palate_is_refused_with_what_to_give(capsys):
    from tonguevis.paths import DATA_DIR

    assert main(["simulate", str(DATA_DIR / "spk1_ta.tsv"), "--epg", "out.csv", "--quiet"]) != 0
    assert "--epg needs --palate" in capsys.readouterr().err
