"""One logger and the verbose convention (issue 24, item 5)."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import pytest

from tonguevis._logging import logger, set_log_level, use_log_level, verbose

PACKAGE = Path(__file__).resolve().parents[1] / "tonguevis"


@pytest.fixture(autouse=True)
def _restore_level():
    old = logger.level
    yield
    logger.setLevel(old)


def test_no_module_makes_its_own_logger():
    """Every module logs through tonguevis._logging.logger: no getLogger anywhere else."""
    makers = [str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py")
              if p.name != "_logging.py" and re.search(r"logging\.getLogger\(", p.read_text())]
    assert makers == []


def test_verbose_sets_the_level_for_one_call_only(caplog):
    @verbose
    def step():
        logger.info("inside")
        return logger.getEffectiveLevel()

    set_log_level("warning")
    with caplog.at_level(logging.DEBUG):  # the handler lets everything through; the logger decides
        logger.setLevel(logging.WARNING)
        assert step(verbose=True) == logging.INFO
        assert step() == logging.WARNING
        assert step(verbose="debug") == logging.DEBUG
    assert [r.getMessage() for r in caplog.records].count("inside") == 2
    assert logger.level == logging.WARNING


def test_verbose_reaches_a_function_that_takes_it_and_bad_values_are_refused():
    @verbose
    def step(verbose=None):
        return verbose

    assert step(verbose="info") == "info"
    with pytest.raises(ValueError, match="verbose"):
        with use_log_level("loud"):
            pass


def test_public_entry_points_take_verbose():
    import inspect

    from tonguevis.analysis.validation import validate
    from tonguevis.sim.simulate import simulate
    from tonguevis.workflows import find_recording_productions, open_recording, simulate_recording

    for function in (simulate, validate, open_recording, find_recording_productions, simulate_recording):
        assert hasattr(function, "__wrapped__") and "verbose" in (function.__doc__ or ""), function.__name__
        inspect.signature(function)  # still introspectable


def test_cli_verbose_says_what_happens(capsys):
    from tonguevis.cli import main
    from tonguevis.paths import REPO_DIR

    demo = REPO_DIR / "data" / "spk1_ta.tsv"
    assert main(["-v", "info", str(demo)]) == 0
    assert logger.getEffectiveLevel() == logging.INFO
    assert main(["info", str(demo)]) == 0
    assert logger.getEffectiveLevel() == logging.WARNING


def test_set_log_level_is_where_the_module_doc_says():
    """Issue 37: the docs say ``tonguevis.set_log_level("warning")``; it was not exported."""
    import tonguevis

    assert "set_log_level" in tonguevis.__all__
    tonguevis.set_log_level("info")
    assert logger.level == logging.INFO
    tonguevis.set_log_level(False)
    assert logger.level == logging.WARNING
