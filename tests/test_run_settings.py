"""One run description all the way down (issue 34): every simulating command takes the same run options, each
reaches the simulation, and ``simulate(recording)`` with no option is ``tonguevis simulate FILE``."""

from __future__ import annotations

import importlib
from pathlib import Path

import numpy as np
import pytest

from tonguevis.cli import build_parser, main
from tonguevis.sim.settings import RunSettings, run_settings

DEMO = "data/spk1_ta.tsv"
REPO = Path(__file__).resolve().parents[1]

#: Every command that simulates, with the arguments it needs besides the run options.
COMMANDS = {
    "simulate": lambda tmp: [DEMO, "--quiet"],
    "segment": lambda tmp: [DEMO, "--out", str(tmp / "s.vtu")],
    "energy": lambda tmp: [DEMO, "--csv", str(tmp / "e.csv"), "--quiet"],
    "morph": lambda tmp: [f"{DEMO}@6.2", f"{DEMO}@6.4", "--out", str(tmp / "m.png"), "--quiet"],
    "batch": lambda tmp: [DEMO, "--out", str(tmp / "batch"), "--quiet"],
    "validate": lambda tmp: [DEMO, "--json", str(tmp / "v.json"), "--quiet"],
    "view": lambda tmp: [DEMO],
    "export-video": lambda tmp: [DEMO, "--out", str(tmp / "v.mp4"), "--quiet"],
    "live": lambda tmp: [],
}

#: (options, the RunSettings fields they set): one non-default value of every run option.
OPTIONS = [
    (["--mesh", "{tmp}/tongue.node"], {"mesh": "{tmp}/tongue.node"}),
    (["--mesh-axes=-x,-z,-y"], {"mesh_axes": "-x,-z,-y"}),
    (["--modes", "37"], {"modes": 37}),
    (["--landmarks", "rule"], {"landmarks": "rule"}),
    (["--method", "linear"], {"method": "linear", "warping": False}),
    (["--linear"], {"method": "linear"}),
    (["--keep-volume"], {"keep_volume": True}),
    (["--sensor-stiffness", "7"], {"sensor_stiffness": 7.0}),
    (["--sensor-stiffness", "hard"], {"sensor_stiffness": None}),
    (["--sensor-patches", "4"], {"sensor_patches": 0.004}),
    (["--no-sensor-patches"], {"sensor_patches": None}),
    (["--fit-rest"], {"rest_fit": True}),
    (["--rest", "0.5", "1.5"], {"rest": (0.5, 1.5)}),
    (["--palate", "generic"], {"palate": "generic"}),
    (["--model-frame"], {"frame": "model"}),
    (["--tongue-size", "1.3"], {"tongue_size": 1.3}),
    (["--tongue-size", "alignment"], {"tongue_size": None}),
    (["--no-closures"], {"closures": False}),
]

#: What the live view cannot do frame by frame: it refuses them, by name (tonguevis.live.simulator).
LIVE_REFUSES = {"keep_volume"}


def _run_options(parser_of_command) -> dict[str, tuple]:
    """{option string: (dest, default)} of the run-options group of a command's parser."""
    for group in parser_of_command._action_groups:
        if group.title and group.title.startswith("how the tongue is simulated"):
            return {s: (a.dest, a.default) for a in group._group_actions for s in a.option_strings}
    return {}


def _subparser(name):
    parser = build_parser()
    action = next(a for a in parser._actions if getattr(a, "choices", None) and name in a.choices)
    return action.choices[name]


def test_every_simulating_command_lists_the_same_run_options_with_the_same_defaults():
    options = {name: _run_options(_subparser(name)) for name in COMMANDS}
    first = options["simulate"]
    dests = {dest for dest, _ in first.values()}
    user_fields = set(RunSettings.names()) - {"warping", "backend", "smooth_window", "tolerance", "frame"}
    assert dests == user_fields | {"linear", "model_frame"}, dests  # frame: --model-frame; --linear: a method
    for name, found in options.items():
        assert found == first, name
    for name in COMMANDS:  # one parser of the values too
        with pytest.raises(SystemExit):
            _subparser(name).parse_args(["x.tsv", "--tongue-size", "large"])
        with pytest.raises(SystemExit):
            _subparser(name).parse_args(["x.tsv", "--sensor-stiffness", "soft"])
    defaults = RunSettings()
    assert first["--modes"][1] == defaults.modes and first["--tongue-size"][1] == defaults.tongue_size
    assert first["--sensor-patches"][1] == defaults.sensor_patches and first["--model-frame"][1] == defaults.frame


class _Reached(Exception):
    """Raised by the stand-in simulation once it has seen the settings."""


@pytest.fixture
def reached(monkeypatch, tmp_path):
    """The RunSettings each command's simulation is called with (the simulation itself replaced)."""
    seen: list[RunSettings] = []
    sim = importlib.import_module("tonguevis.sim.simulate")  # the module: tonguevis.sim.simulate is the function

    def simulate(recording, settings=None, model=None, **overrides):
        names = set(RunSettings.names())
        seen.append(run_settings(settings, **{k: v for k, v in overrides.items() if k in names}))
        raise _Reached

    monkeypatch.setattr(sim, "simulate", simulate)
    import tonguevis.cli._common as common
    import tonguevis.batch.settings as batch_settings

    import tonguevis.workflows.simulation as workflow
    from tonguevis.sim import TongueModel

    for module in (common, importlib.import_module("tonguevis.cli.simulate"),
                   importlib.import_module("tonguevis.cli.validate")):
        monkeypatch.setattr(module, "load_model_args", lambda args: TongueModel.default())  # --mesh: not read
    monkeypatch.setattr(workflow, "build_model", lambda settings: object())
    monkeypatch.setattr(batch_settings.ModelSpec, "build", lambda self: TongueModel.default())  # --mesh: not read
    import tonguevis.gui.app as app  # the app and the live view: the settings they were started with
    import tonguevis.gui.live_window as live_window

    monkeypatch.setattr(app, "run_view", lambda file, settings, **kw: seen.append(settings) or 0)
    monkeypatch.setattr(live_window, "run_live", lambda address, settings, **kw: seen.append(settings) or 0)
    monkeypatch.chdir(REPO)
    return seen


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_run_option_reaches_the_simulation_of_every_command(command, reached, tmp_path, capsys):
    """``tonguevis energy`` took --method, --keep-volume, --fit-rest, --model-frame and --tongue-size and ignored
    them; validate, view, export-video and live lacked some: each command's run now hands every option to the
    simulation."""
    for options, expected in OPTIONS:
        options = [o.format(tmp=tmp_path) for o in options]
        expected = {k: v.format(tmp=tmp_path) if isinstance(v, str) else v for k, v in expected.items()}
        reached.clear()
        argv = [command, *COMMANDS[command](tmp_path), *options]
        if command == "live" and set(expected) & LIVE_REFUSES:
            capsys.readouterr()
            assert main(argv) == 2 and "whole recording" in capsys.readouterr().err
            continue
        try:
            main(argv)
        except _Reached:
            pass
        assert reached, (command, options)
        settings = reached[0]
        for name, value in expected.items():
            got = getattr(settings, name)
            got = getattr(got, "interval", got)  # a rest given reaches the simulation as a RestChoice
            if isinstance(value, float):
                assert got == pytest.approx(value), (command, options, name)
            else:
                assert got == value, (command, options, name, got)
        # Nothing else changed (the rest aside: validate hands the simulation the rest it found).
        untouched = RunSettings().replace(**{k: getattr(settings, k) for k in expected if k != "rest"})
        assert settings.replace(rest=None) == untouched, (command, options)


def test_energy_curves_change_with_the_method_and_the_size(tmp_path):
    """The bug as a user met it: ``energy --method linear`` and ``--tongue-size 1.3`` wrote the default's curves."""
    import os

    os.chdir(REPO)
    out = {}
    for name, extra in (("default", []), ("linear", ["--method", "linear"]), ("size", ["--tongue-size", "1.3"])):
        path = tmp_path / f"{name}.csv"
        assert main(["energy", DEMO, "--csv", str(path), "--quiet", "--modes", "30", *extra]) == 0
        out[name] = path.read_text()
    assert out["linear"] != out["default"] and out["size"] != out["default"]


OPTI = REPO.parent / "shared" / "data" / "ema" / "optispeech"


@pytest.mark.skipif(not OPTI.is_dir(), reason="needs ../shared/data/ema/optispeech (the real recordings)")
def test_the_library_simulates_as_the_command_line_does_on_a_real_recording(tmp_path):
    """Two sets of defaults: simulate(recording) left a real /ka/'s sensors up to 6 mm off the tongue where
    `tonguevis simulate` put them on it.  One set now: the same motion, to the bit."""
    from tonguevis import simulate
    from tonguevis.io import read_recording
    from tonguevis.sim import Motion

    path = OPTI / "006_OSN12_Kah_nofb_natural_take2_HR.tsv"
    assert main(["simulate", str(path), "--quiet", "--out", str(tmp_path)]) == 0
    cli = Motion.load(tmp_path / "motion.npz")
    library = simulate(read_recording(path))
    assert np.array_equal(cli.q, library.q)
    assert library.metadata["sensor_patches"]["radius_mm"] > 0 and library.metadata["fit"]["tongue_size"] is not None
    sensors = library.targets
    surface = np.stack([library.model.mesh.points[library.sensor_nodes] + library.displacement(i)[library.sensor_nodes]
                        for i in range(0, library.n_frames, 50)])
    assert np.nanmax(np.linalg.norm(surface - sensors[::50], axis=2)) < 1e-4  # the sensors on the tongue


def test_overrides_go_with_the_settings_and_an_unknown_one_is_named():
    from tonguevis.errors import SimulationError
    from tonguevis.sim import simulate

    settings = RunSettings(modes=40)
    assert settings.replace(warping=False).method == "linear" and settings.replace(method="domains").warping is False
    with pytest.raises(SimulationError, match="unknown run setting.*mdoes.*the settings are"):
        settings.replace(mdoes=60)
    from tonguevis.io import Recording

    rec = Recording(rate=100.0, times=np.arange(3) / 100.0, sensors={"TT": np.zeros((3, 3))},
                    metadata={"file": "take.tsv"})
    with pytest.raises(SimulationError, match="take.tsv: unknown run setting"):
        simulate(rec, settings, mdoes=60)


def test_the_batch_cache_key_is_every_setting():
    """The batch hashed a hand-written list of settings: a setting left out of it (the palate) reused results
    simulated without it.  Every field changes the key now."""
    from tonguevis.batch import BatchSettings

    base = BatchSettings().step_settings("simulate")
    for name, value in (("palate", "generic"), ("smooth_window", 9), ("tolerance", 1e-6), ("backend", "numpy"),
                        ("keep_volume", True), ("method", "domains"), ("tongue_size", 1.2), ("landmarks", "rule")):
        assert BatchSettings(**{name: value}).step_settings("simulate") != base, name
