"""One name, one meaning across the commands (issue 27): global options, reader options, renamed options."""

from __future__ import annotations

import logging

import pytest

from tonguevis.cli import main


@pytest.fixture
def view_calls(monkeypatch):
    """``tonguevis view``'s run replaced: the arguments it got, no window opened."""
    import tonguevis.cli.view as view

    calls = []
    monkeypatch.setattr(view, "run", lambda args: calls.append(args) or 0)
    return calls


@pytest.mark.parametrize("argv", [[], ["-v"], ["--verbose"]])
def test_global_options_alone_open_the_demo_as_no_arguments_do(argv, view_calls, monkeypatch):
    levels = []
    monkeypatch.setattr(logging, "basicConfig", lambda **kw: levels.append(kw["level"]))
    assert main(argv) == 0
    (args,) = view_calls
    assert args.command == "view" and args.file is None and args.verbose == bool(argv)
    assert levels == [logging.INFO if argv else logging.WARNING]


def test_sensor_stiffness_has_the_same_words_in_the_library_and_the_cli(monkeypatch, capsys):
    """Issue 27, item 12: 'hard' was the CLI's word only; the library ended in NumPy's isfinite TypeError."""
    import importlib

    import numpy as np

    from tonguevis.batch import BatchSettings
    from tonguevis.cli import build_parser
    from tonguevis.errors import SimulationError
    from tonguevis.io import Recording
    from tonguevis.sensor_stiffness import sensor_stiffness_value
    from tonguevis.workflows import simulate_recording

    for value, expected in [("hard", None), (" Hard ", None), (None, None), ("default", "default"), ("20", 20.0),
                            (5, 5.0), (0.5, 0.5)]:
        assert sensor_stiffness_value(value) == expected
    for wrong in ("soft", "", 0, -1, float("inf"), float("nan"), True, [20]):
        with pytest.raises(SimulationError, match="positive number.*'hard'"):
            sensor_stiffness_value(wrong)

    seen = []
    sim = importlib.import_module("tonguevis.sim.simulate")  # the module: tonguevis.sim.simulate is the function
    monkeypatch.setattr(sim, "simulate", lambda recording, settings, model, **kw: seen.append(
        sim.run_settings(settings, **{k: v for k, v in kw.items() if k != "progress"}).sensor_stiffness))
    rec = Recording(rate=100.0, times=np.arange(3) / 100.0, sensors={"TT": np.zeros((3, 3))},
                    metadata={"file": "take.tsv"})
    simulate_recording(rec, object(), sensor_stiffness="hard")
    simulate_recording(rec, object(), sensor_stiffness="default")
    assert seen == [None, "default"]  # the words normalised once, in the settings
    monkeypatch.undo()  # the real simulation: a bad word is said naming the recording, before anything runs
    with pytest.raises(SimulationError, match=r"take.tsv: sensor stiffness 'soft' is neither a positive number"):
        simulate_recording(rec, object(), sensor_stiffness="soft")
    assert BatchSettings(sensor_stiffness="hard").sensor_stiffness is None

    parser = build_parser()
    assert parser.parse_args(["simulate", "x.tsv", "--sensor-stiffness", "hard"]).sensor_stiffness is None
    with pytest.raises(SystemExit):
        parser.parse_args(["simulate", "x.tsv", "--sensor-stiffness", "soft"])
    assert "'soft' is neither a positive number nor one of 'default', 'hard'" in capsys.readouterr().err


class _Read(Exception):
    """Raised by the stand-in reader once it has seen the options (no command runs further)."""


DEMO = "data/spk1_ta.tsv"

#: Every command that reads a recording, with -O audio=false (palate's traces are read by tonguevis.palate).
READING_COMMANDS = {
    "info": ["info", DEMO],
    "syllables": ["syllables", DEMO],
    "convert": ["convert", DEMO, "out.csv"],
    "simulate": ["simulate", DEMO, "--quiet"],
    "validate": ["validate", DEMO, "--json", "v.json"],
    "segment": ["segment", DEMO, "--out", "s.vtu"],
    "energy": ["energy", DEMO, "--csv", "e.csv"],
    "morph": ["morph", f"{DEMO}@6.2", f"{DEMO}@6.4", "--out", "m.png"],
    "export-video": ["export-video", DEMO, "--out", "v.mp4"],
    "palate": ["palate", DEMO, "--out", "p.stl"],
}


@pytest.mark.parametrize("command", sorted(READING_COMMANDS))
def test_every_command_that_reads_a_recording_takes_reader_options(command, monkeypatch, tmp_path, capsys):
    """Issue 27, item 7: the README says -O audio=false works for any command; only info and convert took -O."""
    import tonguevis.cli.energy as energy_cli
    import tonguevis.cli.morph as morph_cli
    import tonguevis.workflows.recording as workflows
    from tonguevis.paths import REPO_DIR

    seen = []

    def reader(path, sensor_map=None, **options):
        seen.append(options)
        raise _Read

    monkeypatch.setattr(workflows, "open_recording", reader)
    monkeypatch.setattr(energy_cli, "load_model", lambda args: None)
    monkeypatch.setattr(morph_cli, "load_model", lambda args: None)
    monkeypatch.chdir(REPO_DIR)
    argv = [a if a.startswith(("data/", "-")) or a == command else str(tmp_path / a) for a in READING_COMMANDS[command]]
    try:
        main([*argv, "-O", "audio=false", "--option", "axes=-y,x,z"])
    except _Read:
        pass
    assert seen and seen[0]["audio"] is False and seen[0]["axes"] == "-y,x,z", capsys.readouterr()


def test_view_and_batch_pass_reader_options_on(monkeypatch, tmp_path):
    import tonguevis.batch as batch
    import tonguevis.gui.app as app

    given = {}
    monkeypatch.setattr(app, "run_view", lambda *a, **kw: given.update(view=kw["reading"]) or 0)
    assert main(["view", DEMO, "-O", "audio=false"]) == 0
    assert given["view"] == {"audio": False}

    def run_batch(paths, out, settings, **kw):
        given["batch"] = settings.read_options
        raise _Read

    monkeypatch.setattr(batch, "run", run_batch)
    with pytest.raises(_Read):
        main(["batch", "data", "--out", str(tmp_path), "-O", "audio=false", "--quiet"])
    assert given["batch"] == (("audio", False),)


def test_one_name_one_meaning_with_the_old_names_kept_for_a_release(capsys):
    """Issue 27, item 8: --reference head|jaw in view and export-video (--frame is view's frame number);
    segment's --modes is a count like everywhere, the local modes' kind is --mode-kind; the mesh's axes
    are --mesh-axes (the recording's are -O axes=).  The old spellings still work, with a note."""
    from tonguevis.cli import build_parser
    from tonguevis.cli.segment import resolve_mode_options

    parser = build_parser()
    assert parser.parse_args(["view", "--reference", "jaw", "--frame", "12"]).reference == "jaw"
    assert parser.parse_args(["export-video", "--out", "v.mp4", "--reference", "jaw"]).reference == "jaw"
    new = parser.parse_args(["segment", DEMO, "--out", "s.vtu", "--modes", "20", "--mode-kind", "rigid"])
    resolve_mode_options(new)
    assert (new.modes, new.mode_kind) == (20, "rigid")
    default = parser.parse_args(["segment", DEMO, "--out", "s.vtu"])
    resolve_mode_options(default)
    assert (default.modes, default.mode_kind) == (100, "constraint")
    for command in (["simulate", DEMO], ["energy", DEMO, "--csv", "e.csv"], ["validate", DEMO, "--json", "v.json"],
                    ["segment", DEMO, "--out", "s.vtu"], ["batch", "data", "--out", "r"],
                    ["morph", f"{DEMO}@1", f"{DEMO}@2", "--out", "m.png"]):
        assert parser.parse_args([*command, "--mesh-axes=-x,-z,-y"]).mesh_axes == "-x,-z,-y"
    assert capsys.readouterr().err == ""

    # The old spellings, one release more: the same values, and a note on stderr.
    assert parser.parse_args(["export-video", "--out", "v.mp4", "--frame", "jaw"]).reference == "jaw"
    assert "--frame is deprecated" in capsys.readouterr().err
    old = parser.parse_args(["segment", DEMO, "--out", "s.vtu", "--modes", "rigid", "--modal-modes", "20"])
    assert "--modal-modes is deprecated" in capsys.readouterr().err
    resolve_mode_options(old)
    assert (old.modes, old.mode_kind) == (20, "rigid")
    assert "--modes rigid is deprecated" in capsys.readouterr().err
    assert parser.parse_args(["simulate", DEMO, "--axes=-x,-z,-y"]).mesh_axes == "-x,-z,-y"
    assert "--axes is deprecated and goes in the next release; use --mesh-axes" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        parser.parse_args(["segment", DEMO, "--out", "s.vtu", "--modes", "many"])
    assert "--mode-kind rigid|constraint" in capsys.readouterr().err


def test_a_silent_video_says_it_is_silent_and_why(monkeypatch, tmp_path, capsys):
    """Issue 27, item 6: export-video of a recording without sound wrote a silent MP4 and said nothing."""
    from types import SimpleNamespace

    import numpy as np

    import tonguevis.workflows.session as session_module
    import tonguevis.workflows.simulation as simulation
    import tonguevis.render.video as video
    from tonguevis.io import Audio, Recording

    sound = {"audio": None}
    recording = lambda: Recording(rate=100.0, times=np.arange(3) / 100.0, sensors={},  # noqa: E731
                                  audio=sound["audio"])
    monkeypatch.setattr(session_module, "load_session", lambda path, **kw: SimpleNamespace(
        recording=recording(), rest=SimpleNamespace(describe=lambda: "rest: given")))
    monkeypatch.setattr(simulation, "simulate_session", lambda session, *a, **kw: None)
    monkeypatch.setattr(video, "export_video", lambda session, out, *a, **kw: out)
    import tonguevis.render.mp4 as mp4  # the file's streams, as the fake export would have written them

    monkeypatch.setattr(mp4, "probe_streams", lambda path: ["video"] + (["audio"] if sound["audio"] else []))
    out = tmp_path / "v.mp4"
    take = tmp_path / "take.tsv"
    assert main(["export-video", str(take), "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert f"note: {out} is silent: take.tsv holds no sound and no take.wav lies beside it" in printed
    assert "--audio FILE" in printed
    assert main(["export-video", str(take), "--out", str(out), "--quiet", "-O", "audio=false"]) == 0
    assert "is silent: the sound was turned off (-O audio=false)" in capsys.readouterr().out
    sound["audio"] = Audio(np.zeros(160), 16000.0)
    assert main(["export-video", str(take), "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "is silent" not in printed and f"{out} (head frame, with the recording's sound)" in printed


def test_batch_simulates_with_the_command_line_method(monkeypatch, tmp_path):
    import tonguevis.batch as batch

    given = {}

    def run_batch(paths, out, settings, **kw):
        given["settings"] = settings
        raise _Read

    monkeypatch.setattr(batch, "run", run_batch)
    with pytest.raises(_Read):
        main(["batch", "data", "--out", str(tmp_path), "--method", "domains", "--no-sensor-patches", "--quiet"])
    settings = given["settings"]
    assert settings.run_settings().method == "domains" and settings.sensor_patches is None
    default = batch.BatchSettings()
    assert settings.step_settings("simulate") != default.step_settings("simulate")  # a different cache key
    assert default.step_settings("simulate")["sensor_patches"] == "default"
