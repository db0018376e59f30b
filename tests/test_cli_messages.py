"""What the commands say on a terminal (issue 37): warnings on lines of their own, not glued onto
the progress bar; each warning once and in one line."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.edge_recordings import demo, write
from tonguevis.paths import DEMO_RECORDING, REPO_DIR


def run_command(*args, timeout: float = 300) -> subprocess.CompletedProcess:
    """``tonguevis ARGS`` as a user runs it, in its own process (its own logging set-up)."""
    return subprocess.run([sys.executable, "-m", "tonguevis", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=REPO_DIR, env=dict(os.environ, PYTHONPATH=str(REPO_DIR)))


def terminal_lines(stream: str) -> list[str]:
    """What a terminal shows of ``stream``: each line as its last carriage return left it."""
    return [line.rsplit("\r", 1)[-1] for line in stream.split("\n")]


@pytest.fixture(scope="module")
def speech_only(tmp_path_factory):
    """The demo's first two /ta/ trains without the rest before them: simulating it warns (no still second)."""
    return write(demo(5.2, 9.2), tmp_path_factory.mktemp("speech") / "speech.csv")


def test_a_warning_during_the_progress_bar_is_a_line_of_its_own(speech_only):
    done = run_command("simulate", speech_only, "--modes", "20")
    assert done.returncode == 0, done.stderr[-2000:]
    assert "simulating:" in done.stderr  # the bar was drawn (not --quiet)
    shown = terminal_lines(done.stderr)
    warnings = [line for line in shown if "WARNING" in line]
    assert warnings, done.stderr
    assert all(line.startswith("tonguevis: WARNING: ") for line in warnings), warnings


def _warnings(caplog) -> list[str]:
    import logging

    return [r.getMessage() for r in caplog.records if r.name == "tonguevis" and r.levelno >= logging.WARNING]


def test_a_warning_is_one_line_said_once_per_process_its_detail_kept(speech_only, caplog):
    """A script simulating the same recording twice hears its warning once, in one line; the whole
    story is at the info level (``verbose=True``, ``tonguevis -v``) and in the run's summary."""
    import logging

    from tonguevis.io import read_recording
    from tonguevis.sim import TongueModel, simulate

    rec = read_recording(speech_only)
    model = TongueModel.default()
    with caplog.at_level(logging.INFO, logger="tonguevis"):
        first = simulate(rec, model, modes=20)
    said, told = _warnings(caplog), caplog.text
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="tonguevis"):
        again = simulate(rec, model, modes=20)
    assert len(said) == 1 and "no still second" in said[0] and "--rest START END" in said[0]
    assert "\n" not in said[0] and len(said[0]) <= 140, said[0]
    assert "longest: " in told and "below 10 mm/s" in told  # the detail, at the info level
    assert _warnings(caplog) == []  # the second run: nothing said again
    for motion in (first, again):
        assert motion.metadata["rest"]["how"] == "stillest window"
        assert motion.metadata["rest"]["reason"] == "no still second in the recording"


def test_a_rest_far_from_the_models_nodes_is_said_in_one_line(caplog):
    """Issue 37: rest sensors 6 mm RMS from their nodes (a held-out Opti-Speech speaker) passed unsaid."""
    import logging

    from tests.sim._models import bar_model
    from tests.sim.test_simulate import SENSORS, _recording
    from tonguevis.sim import simulate
    from tonguevis.sim.placement import REST_MISFIT_MM

    model = bar_model(sensors=SENSORS)
    good = _recording(model)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        motion = simulate(good, model, modes=20, backend="numpy")
    assert motion.metadata["fit"]["residual_rms_mm"] < REST_MISFIT_MM and _warnings(caplog) == []
    off = good.with_sensors({**good.sensors, "TD": good.sensors["TD"] + [0.0, 0.0, 0.02]})  # TD 2 cm off its node
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        motion = simulate(off, model, modes=20, backend="numpy")
    fit = motion.metadata["fit"]
    assert fit["residual_rms_mm"] > REST_MISFIT_MM
    said = [m for m in _warnings(caplog) if "from their nodes" in m]
    assert said == [f"synthetic: the rest sensors lie {fit['residual_rms_mm']:.1f} mm RMS from their nodes "
                    f"(TD {fit['residual_by_sensor_mm']['TD']:.1f} mm): the model's rest shape is not this "
                    "speaker's (--fit-rest bends it onto them)"]


def test_a_real_clinic_recording_says_each_warning_once_in_a_line(tmp_path):
    """The Opti-Speech /ta/ against the speaker's palate: no still second and a rest spread no adult
    tongue has, each a line of its own, none repeated (the palate's placement is said at the info
    level), and the summary on stdout holds the figures."""
    from tests.conftest import shared_file

    traces = [shared_file("ema", "optispeech", f"00{k}_OSN12_Palate_{kind}_HR.tsv")
              for k, kind in ((2, "MidSagital"), (3, "Coronal"), (4, "Scribble"))]
    speech = shared_file("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv")
    palate = tmp_path / "palate.stl"
    assert run_command("palate", *traces, "--out", palate).returncode == 0
    done = run_command("simulate", speech, "--palate", palate, "--quiet")
    assert done.returncode == 0, done.stderr[-2000:]
    warnings = [line for line in terminal_lines(done.stderr) if "WARNING" in line]
    assert len(warnings) == len(set(warnings)) == 2, warnings
    assert all(len(line) <= 180 for line in warnings), warnings  # were 320-420 characters
    assert "rest: " in done.stdout and "stillest window" in done.stdout
    assert "times that volume, is no adult's" in done.stdout and "the speaker's palate: " in done.stdout


def test_info_says_the_rest_a_simulation_would_take(speech_only, capsys):
    """What the warning says briefly, `tonguevis info` says as a line of the recording's description."""
    from tonguevis.cli import main

    assert main(["info", str(speech_only)]) == 0
    out, err = capsys.readouterr()
    rest = [line for line in out.splitlines() if line.startswith("rest:")]
    assert len(rest) == 1 and rest[0].endswith("(stillest window: no still second in the recording)"), out
    assert "WARNING" not in err
    assert main(["info", str(DEMO_RECORDING)]) == 0
    assert "(detected: the longest still stretch)" in capsys.readouterr().out


def test_a_recording_given_as_the_palate_points_to_tonguevis_palate(tmp_path, capsys):
    """Issue 37: `--palate TRACE.tsv` said "Could not deduce file format from path"."""
    from tonguevis.cli import main

    trace = write(demo(3.0, 4.0), tmp_path / "trace.tsv")  # any recording: traces are recordings
    code = main(["simulate", str(DEMO_RECORDING), "--palate", str(trace), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert str(trace) in err[0] and "not a palate surface" in err[0] and "`tonguevis palate TRACE.tsv" in err[0]
