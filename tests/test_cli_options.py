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
    monkeypatch.setattr(sim, "simulate", lambda recording, model, **kw: seen.append(kw["sensor_stiffness"]))
    rec = Recording(rate=100.0, times=np.arange(3) / 100.0, sensors={"TT": np.zeros((3, 3))},
                    metadata={"file": "take.tsv"})
    simulate_recording(rec, object(), sensor_stiffness="hard")
    simulate_recording(rec, object(), sensor_stiffness="default")
    assert seen == [None, "default"]
    with pytest.raises(SimulationError, match=r"take.tsv: sensor stiffness 'soft' is neither a positive number"):
        simulate_recording(rec, object(), sensor_stiffness="soft")
    assert BatchSettings(sensor_stiffness="hard").sensor_stiffness is None

    parser = build_parser()
    assert parser.parse_args(["simulate", "x.tsv", "--sensor-stiffness", "hard"]).sensor_stiffness is None
    with pytest.raises(SystemExit):
        parser.parse_args(["simulate", "x.tsv", "--sensor-stiffness", "soft"])
    assert "'soft' is neither a positive number nor one of 'default', 'hard'" in capsys.readouterr().err
