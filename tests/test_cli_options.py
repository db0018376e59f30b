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
