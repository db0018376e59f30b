"""What the commands say on a terminal (issue 37): warnings on lines of their own, not glued onto
the progress bar; each warning once and in one line."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.edge_recordings import demo, write
from tonguevis.paths import REPO_DIR


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
