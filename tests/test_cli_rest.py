"""Every command that simulates, on recordings without a rest: none dead-ends, each says which rest it used.

Recordings: two cut from the demo /ta/ (speech from the first frame, 4 s; and
2.5 s), the real Opti-Speech /ta/ (009) and /ka/ (006) and the Haskins sentence.
``view`` and ``export-video`` need Qt: tests/gui/test_rest_interval.py runs them.
"""

from __future__ import annotations

import re
from dataclasses import replace

import pytest

from tests.conftest import shared_file
from tonguevis.cli import main
from tonguevis.paths import DATA_DIR

pytestmark = pytest.mark.slow

STILLEST = re.compile(r"rest: \d+\.\d\d-\d+\.\d\d s \(stillest window: no still second in the recording\)")
REAL = {
    "optispeech-ta": (("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv"), []),
    "optispeech-ka": (("ema", "optispeech", "006_OSN12_Kah_nofb_natural_take2_HR.tsv"), []),
    "haskins": (("ema", "mview", "F01_B01_S01_R01_N.mat"), ["--sensors", "haskins"]),
}


def cut_demo(folder, name: str, start: float, end: float):
    """The demo /ta/ from ``start`` to ``end`` s, clock from 0, as a CSV in ``folder`` (no rest in it)."""
    from tonguevis.io import write_recording
    from tonguevis.workflows import open_recording

    demo = DATA_DIR / "spk1_ta.tsv"
    if not demo.exists():
        pytest.skip(f"demo corpus not built: {demo}")
    rec = open_recording(demo)
    keep = (rec.times >= start) & (rec.times <= end)
    cut = replace(rec, times=rec.times[keep] - rec.times[keep][0], audio=None, labels=[],
                  sensors={n: v[keep] for n, v in rec.sensors.items()},
                  orientations={n: v[keep] for n, v in rec.orientations.items()})
    path = folder / f"{name}.csv"
    write_recording(cut, path)
    return path


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("no_rest")
    return {"speech-from-first-frame": cut_demo(folder, "speech", 5.2, 9.2),
            "under-3-s": cut_demo(folder, "short", 5.2, 7.7)}


def recording(which: str, generated) -> tuple[str, list[str]]:
    if which in REAL:
        parts, options = REAL[which]
        return str(shared_file(*parts)), options
    return str(generated[which]), []


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


COMMANDS = {  # command -> extra arguments (files go to OUT)
    "simulate": lambda f, out: ["simulate", f],
    "energy": lambda f, out: ["energy", f, "--csv", out / "e.csv"],
    "segment": lambda f, out: ["segment", f, "--out", out / "s.vtu", "--mode-kind", "rigid", "--seeds", "2"],
    "morph": lambda f, out: ["morph", f"{f}@0.5", f"{f}@1.5", "--out", out / "m.png"],
    "validate": lambda f, out: ["validate", f, "--json", out / "v.json", "--no-static"],
}


@pytest.mark.parametrize("which", ["speech-from-first-frame", "under-3-s", *REAL])
def test_every_command_finds_a_rest_and_says_which(which, generated, tmp_path, capsys, caplog):
    path, options = recording(which, generated)
    lines = {}
    for command, arguments in COMMANDS.items():
        caplog.clear()
        code, out, err = run(capsys, *arguments(path, tmp_path), *options, "--quiet")
        assert code == 0, (command, err[-2000:])
        found = STILLEST.search(out)
        assert found, (command, out)
        lines[command] = found.group(0)
        # The warning says how to give one.
        assert "no still second" in caplog.text and "--rest START END" in caplog.text, command
    assert len(set(lines.values())) == 1, lines  # one rest, found the same way by every command


def test_a_given_rest_is_used_and_reported(generated, tmp_path, capsys, caplog):
    path = str(generated["under-3-s"])
    for command, arguments in COMMANDS.items():
        caplog.clear()
        code, out, err = run(capsys, *arguments(path, tmp_path), "--rest", "0.3", "0.6", "--quiet")
        assert code == 0, (command, err[-2000:])
        assert "rest: 0.30-0.60 s (given)" in out, (command, out)
        assert "stillest" not in caplog.text, command
    doc = (tmp_path / "v.json").read_text()
    assert '"rest_interval_from": "given"' in doc


@pytest.mark.parametrize("rest, problem", [
    (("1.0", "9.0"), "is not inside the recording (0.00-2.50 s)"),
    (("-3", "-1"), "is not inside the recording"),
    (("0.6", "0.3"), "the end must come after the start"),
])
def test_a_bad_rest_is_a_one_line_error_naming_the_file(rest, problem, generated, tmp_path, capsys):
    path = generated["under-3-s"]
    for command, arguments in COMMANDS.items():
        code, out, err = run(capsys, *arguments(str(path), tmp_path), "--rest", *rest, "--quiet")
        assert code == 2, (command, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and path.name in lines[0] and problem in lines[0], (command, err)
        assert lines[0].startswith(f"tonguevis {command}: error:"), lines[0]


def test_the_rest_option_is_documented_on_every_simulating_command(capsys):
    for command in (*COMMANDS, "view", "export-video"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert "--rest START END" in capsys.readouterr().out, command
