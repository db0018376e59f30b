"""The README's commands stay true for someone with a fresh clone: every command parses, reads
only the demo in data/ or a placeholder, and the cheap ones run as written."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from tonguevis.cli import build_parser, main
from tonguevis.paths import DATA_DIR, REPO_DIR

README = REPO_DIR / "README.md"
#: Commands quick enough to run here (the others simulate; their own tests run them).
CHEAP = ("info", "syllables", "convert", "measures", "export-wav")
#: Arguments of the commands that name the recordings they read.
INPUTS = ("file", "input", "paths", "source", "target", "compare")


def readme_commands() -> list[list[str]]:
    """The arguments of every ``tonguevis ...`` line of the README's bash blocks."""
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S):
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            if words and words[0] == "tonguevis":
                commands.append(words[1:])
    return commands


COMMANDS = readme_commands()


def inputs(args: list[str]) -> list[str]:
    """The recordings (or folders) a command reads, as written."""
    namespace = build_parser().parse_args(args or ["view"])
    found = []
    for name in INPUTS:
        value = getattr(namespace, name, None)
        for item in value if isinstance(value, list) else [value]:
            if item is None:
                continue
            path = item[0] if isinstance(item, tuple) else item  # morph's FILE@TIME
            found.append(Path(path).as_posix())
    return found


def is_placeholder(path: str) -> bool:
    """``RECORDING.mat``-like names: capitals that cannot be mistaken for a real file."""
    return re.fullmatch(r"[A-Z][A-Z_]*(\.\w+)?", Path(path).name) is not None


def test_readme_shows_the_commands():
    assert len(COMMANDS) >= 10
    assert {args[0] for args in COMMANDS if args} >= {"view", "info", "syllables", "convert", "validate"}


@pytest.mark.parametrize("args", COMMANDS, ids=lambda args: " ".join(args) or "(no arguments)")
def test_readme_command_reads_files_a_user_has(args):
    try:
        files = inputs(args)
    except SystemExit:
        pytest.fail(f"`tonguevis {' '.join(args)}` does not parse")
    assert not any(".." in Path(word).parts for word in args), "points outside the clone"
    for path in files:
        assert is_placeholder(path) or (Path(path).parts[0] == "data" and (REPO_DIR / path).exists()), (
            f"`tonguevis {' '.join(args)}` reads {path}: neither a demo file in data/ nor a placeholder")


def test_readme_code_names_only_demo_files_that_exist():
    text = README.read_text(encoding="utf-8")
    named = set(re.findall(r"(?<![\w/.])data/[\w.-]+", text))
    assert named
    for path in named:
        assert (REPO_DIR / path).exists(), path


@pytest.mark.parametrize("args", [a for a in COMMANDS if a and a[0] in CHEAP  # a placeholder is the user's file
                                  and not any(is_placeholder(p) for p in inputs(a))], ids=" ".join)
def test_readme_command_runs_as_written(args, tmp_path, monkeypatch, capsys):
    if not DATA_DIR.exists():
        pytest.skip("no demo corpus")
    (tmp_path / "data").symlink_to(DATA_DIR, target_is_directory=True)  # a clone's root; outputs stay here
    monkeypatch.chdir(tmp_path)
    code = main(args)
    err = capsys.readouterr().err
    assert code == 0, err
    assert "error" not in err


def test_readme_opens_the_batch_tables_with_what_tonguevis_installs(tmp_path, monkeypatch):
    """Issue 27, item 10: the README said pandas, which `.[all]` does not install; its snippet runs as written."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    blocks = [b for b in re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
              if "results/energy.parquet" in b]
    assert len(blocks) == 1, "the README shows how to open the batch tables in Python"
    assert "pandas" not in blocks[0] and "pd." not in blocks[0]
    (tmp_path / "results").mkdir()
    pq.write_table(pa.table({"speaker": ["spk1", "spk1"], "syllable": ["ta", "ta"], "energy_J": [1e-3, 2e-3]}),
                   tmp_path / "results" / "energy.parquet")
    monkeypatch.chdir(tmp_path)
    exec(compile(blocks[0], "README.md", "exec"), {})


def test_the_readme_documents_how_the_tongue_follows_the_sensors():
    """Issue 37: --method and --keep-volume, which every simulating command takes, were nowhere in the
    README. Every option of a run (tonguevis.cli._common.add_run_arguments) is."""
    import argparse

    from tonguevis.cli._common import add_run_arguments

    parser = argparse.ArgumentParser()
    add_run_arguments(parser)
    options = [o for a in parser._actions for o in a.option_strings
               if o.startswith("--") and o != "--help" and a.help != argparse.SUPPRESS]
    text = README.read_text(encoding="utf-8")
    assert {"--method", "--keep-volume"} <= set(options)
    missing = [o for o in options if not re.search(re.escape(o) + r"(?![\w-])", text)]
    assert missing == []
    simulate = next(a for a in build_parser()._actions if a.dest == "command").choices["simulate"]
    for method in simulate._option_string_actions["--method"].choices:
        assert f"`--method {method}`" in text


def test_the_readme_gives_the_palate_fit_tonguevis_palate_prints(tmp_path, capsys):
    """Issue 37: the README gave two residuals for the fit of the same traces (0.88 and 0.76 mm)."""
    from tests.conftest import shared_file

    traces = [shared_file("ema", "optispeech", f"00{k}_OSN12_Palate_{kind}_HR.tsv")
              for k, kind in ((2, "MidSagital"), (3, "Coronal"), (4, "Scribble"))]
    assert main(["palate", *map(str, traces), "--out", str(tmp_path / "palate.stl")]) == 0
    out = capsys.readouterr().out
    rms = re.search(r"RMS distance to the surface (\d+\.\d\d) mm", out).group(1)
    bend = re.search(r"tightest bend (\d+\.\d) mm", out).group(1)
    said = re.findall(r"Opti-Speech traces now fit with (\d+\.\d\d) mm RMS, tightest bend (\d+\.\d) mm",
                      " ".join(README.read_text(encoding="utf-8").split()))
    assert said == [(rms, bend)]
