"""``tonguevis syllables`` prints the production table, writes CSV, fails in one line."""

import csv

from tonguevis.cli import main
from tonguevis.paths import DATA_DIR


def test_syllables_on_the_demo(capsys, tmp_path):
    out_csv = tmp_path / "p.csv"
    assert main(["syllables", str(DATA_DIR / "spk1_ta.tsv"), "--csv", str(out_csv)]) == 0
    text = capsys.readouterr().out
    assert "head motion removed with REF1, REF2, REF3" in text
    assert "productions found per train: 5, 5, 5, 5, 5" in text
    body = [line for line in text.splitlines() if line[:5].strip().isdigit()]
    assert len(body) == 15 and all(line.split()[1] in {"2", "3", "4"} for line in body)
    rows = list(csv.DictReader(out_csv.open()))
    header = text.splitlines()[[i for i, line in enumerate(text.splitlines()) if line[:5].strip().isdigit()][0] - 1]
    # units in every time column, the same names on screen and on disk
    assert list(rows[0]) == header.split() == ["train", "index", "label", "articulator", "start_s", "end_s",
                                               "release_s", "closure_s", "vowel_s", "duration_ms", "clarity"]
    assert len(rows) == 15 and {r["label"] for r in rows} == {"ta"} and {r["articulator"] for r in rows} == {"TT"}


def test_syllables_all_and_kinematic_fallback(capsys, tmp_path):
    assert main(["syllables", str(DATA_DIR / "spk3_la.tsv"), "--all", "--sensors", "paper"]) == 0
    text = capsys.readouterr().out
    assert "(25)" in text and "audio envelope" in text


def test_syllables_errors_in_one_line(capsys, tmp_path):
    assert main(["syllables", str(tmp_path / "missing.tsv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing.tsv" in err
    # without a sensor map the NDI channels are S0..S7: no TT
    lone = tmp_path / "x.tsv"
    lone.write_bytes((DATA_DIR / "spk1_ta.tsv").read_bytes())
    assert main(["syllables", str(lone)]) == 2
    err = capsys.readouterr().err
    assert "tongue-tip (TT)" in err and "x.tsv" in err and err.count("\n") == 1


def test_syllables_writes_the_gesture_landmarks(capsys, tmp_path):
    import pyarrow.parquet as pq

    out = tmp_path / "g.parquet"
    assert main(["syllables", str(DATA_DIR / "spk1_ka.tsv"), "--all", "--gestures", str(out)]) == 0
    text = capsys.readouterr().out
    assert "articulator: TD (/ka/ (from the file name): the dorsum (TD))" in text
    assert f"wrote {out} (gesture landmarks of 25 productions)" in text
    table = pq.read_table(out).to_pydict()
    assert table["label"] == ["ka"] * 25 and set(table["articulator"]) == {"TD"}
    for k in range(25):
        times = [table[f"{name}_s"][k] for name in ("gons", "pvel", "nons", "maxc", "noffs", "pvel2", "goffs")]
        assert times == sorted(times)


def test_a_clean_session_of_isolated_ta_is_clear(capsys, tmp_path):
    """Issue 37: a held-out /ta/ session with 10 clear productions was called "unclear ... a guess". The tip
    rests high in isolated /ta/, so its rise from the opening dip is small (0.34 of the range for the certain
    /ta/ of Opti-Speech 009) and every production was rated weak; the fall to the vowel tells a clear one."""
    from tests.edge_recordings import write
    from tests.preprocess._synthetic import isolated_ta_session

    path = write(isolated_ta_session(), tmp_path / "session_ta.tsv")
    assert main(["syllables", str(path)]) == 0
    out, err = capsys.readouterr()
    body = [line for line in out.splitlines() if line[:5].strip().isdigit()]
    assert len(body) == 10 and all(float(line.split()[-1]) == 1.0 for line in body), out
    assert "unclear" not in out and "a guess" not in err
