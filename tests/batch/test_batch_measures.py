"""The batch's measures step (issue 35): tonguevis measures per recording, the STI and averages per group."""

from __future__ import annotations

import json

import numpy as np
import pytest

pq = pytest.importorskip("pyarrow.parquet")

from tests.batch.test_batch import corpus  # noqa: E402,F401  (the fixture: three generated recordings)
from tonguevis.batch import run  # noqa: E402
from tonguevis.cli import main  # noqa: E402


def _table(path):
    return pq.read_table(path).to_pydict()


def test_measures_equal_tonguevis_measures_and_groups_pool_them(corpus, tmp_path, capsys):  # noqa: F811
    out = tmp_path / "out"
    result = run(corpus, out, steps="measures")
    assert result.ok and result.timings["prepare"] == 0.0  # no simulation: no modal basis
    measures = _table(out / "measures.parquet")
    assert set(measures["recording"]) == {"spk1_ta", "spk2_ka", "spk3_la"}
    document = tmp_path / "one.json"
    assert main(["measures", str(corpus / "spk2_ka.tsv"), "--json", str(document)]) == 0
    single = json.loads(document.read_text())
    mine = [i for i, r in enumerate(measures["recording"]) if r == "spk2_ka"]
    for key in ("closure_s", "constriction_degree_mm", "peak_velocity_closing_mm_s", "stiffness_closing_per_s"):
        assert [measures[key][i] for i in mine] == pytest.approx([row[key] for row in single["measures"]], rel=1e-12)
    repetitions = _table(out / "repetitions.parquet")  # by speaker and syllable: one recording per group
    for sensor, sti in single["sti"].items():
        row = [i for i, (g, s) in enumerate(zip(repetitions["group"], repetitions["sensor"]))
               if g == "spk2 ka" and s == sensor]
        assert len(row) == 1 and repetitions["sti"][row[0]] == pytest.approx(sti, abs=1e-6)
        assert repetitions["n"][row[0]] == single["n"] and repetitions["recordings"][row[0]] == 1
    averages = _table(out / "averages.parquet")
    assert len(averages["group"]) == len(repetitions["group"]) * 101


def test_a_coarser_group_pools_the_recordings(corpus, tmp_path):  # noqa: F811
    from tonguevis.analysis.repetitions import sti_of

    out = tmp_path / "out"
    run(corpus, out, steps="measures", group_by="trial")  # every recording is trial 1: one group of all
    trajectories = _table(out / "trajectories.parquet")
    repetitions = _table(out / "repetitions.parquet")
    row = repetitions["sensor"].index("TT")
    assert repetitions["recordings"][row] == 3 and repetitions["group"][row] == "1"
    tip = [i for i, s in enumerate(trajectories["sensor"]) if s == "TT"]
    records = np.array([trajectories["zscore"][i] for i in tip]).reshape(-1, 101)
    assert repetitions["n"][row] == len(records)
    assert repetitions["sti"][row] == pytest.approx(sti_of(records), abs=1e-12)
    one = run(corpus, tmp_path / "again", steps="measures", group_by="speaker,syllable")
    split = _table(one.out / "repetitions.parquet")
    assert {g for g, s in zip(split["group"], split["sensor"]) if s == "TT"} == {"spk1 ta", "spk2 ka", "spk3 la"}


def test_bad_group_is_an_error(tmp_path, capsys):
    assert main(["batch", str(tmp_path), "--out", str(tmp_path / "o"), "--steps", "measures",
                 "--group-by", "colour"]) == 2
    assert "group_by colour" in capsys.readouterr().err


def test_the_label_table_is_a_setting_and_groups_by_its_speakers(corpus, tmp_path):  # noqa: F811
    """``labels=`` (a BatchSettings field, as ``tonguevis batch --labels``) names the speakers: two recordings of
    one speaker pool into one group; a changed row redoes that recording only."""
    table = tmp_path / "labels.csv"
    table.write_text("file,speaker\nspk1_ta.tsv,anna\nspk2_ka.tsv,anna\nspk3_la.tsv,ben\n")
    out = tmp_path / "out"
    result = run(corpus, out, steps="measures", group_by="speaker", labels=table)
    assert result.ok and len(result.done) == 3
    groups = set(_table(out / "repetitions.parquet")["group"])
    assert groups == {"anna", "ben"}
    assert json.loads((out / "batch.json").read_text())["settings"]["labels"] == str(table)
    table.write_text("file,speaker\nspk1_ta.tsv,anna\nspk2_ka.tsv,anna\nspk3_la.tsv,carl\n")
    again = run(corpus, out, steps="measures", group_by="speaker", labels=table)
    assert len(again.done) == 1 and "spk3_la" in str(again.done[0]) and len(again.up_to_date) == 2
    assert set(_table(out / "repetitions.parquet")["group"]) == {"anna", "carl"}


def test_workers_are_a_count_a_client_or_slurm_options(corpus, tmp_path):  # noqa: F811
    from tonguevis.batch import BatchError

    for bad in (0, -1, "two", True, None):
        with pytest.raises(BatchError, match="workers must"):
            run(corpus, tmp_path / "out", steps="measures", workers=bad)
