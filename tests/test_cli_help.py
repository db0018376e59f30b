"""The commands' help says what the options do and cost in a user's words (issue 37)."""

from __future__ import annotations

from tonguevis.cli import build_parser


def help_of(command: str, option: str) -> str:
    """The ``--help`` text of ``option`` of ``tonguevis command``."""
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices[command]
    return next(a.help for a in sub._actions if option in a.option_strings)


def test_the_domains_method_is_said_at_the_speed_it_runs():
    """--method's help said "tens of frames/s" for a method that runs a few hundred (scripts/bench_domains.py:
    300-500 frames/s whole trial on 2 cores, the modal methods 6,000-24,000), and "seed 001", a name
    only this project uses."""
    commands = next(a for a in build_parser()._actions if a.dest == "command").choices
    having = [name for name, sub in commands.items() if "--method" in sub._option_string_actions]
    assert {"simulate", "energy", "segment", "morph", "batch"} <= set(having)
    for command in having:
        said = help_of(command, "--method")
        assert "a few hundred frames/s" in said and "the modal methods thousands" in said, said
        assert "Luo et al. 2017" in said and "tens of" not in said and "seed" not in said


def test_a_colouring_has_one_name_in_the_app_and_on_the_command_line():
    """Issue 37: `--color contact` was "distance to palate" in the app. Each of the app's Colour by entries
    starts with the command line's name, and the options' help gives the app's words for it."""
    import pytest

    pytest.importorskip("PySide6")
    from tonguevis.appstate import COLOR_MODES
    from tonguevis.cli.view import COLOR_CHOICES
    from tonguevis.gui.view3d import COLOUR_LABELS

    assert set(COLOR_CHOICES) == set(COLOR_MODES) == set(COLOUR_LABELS)
    helps = [help_of("view", "--color"), help_of("export-video", "--color")]
    for mode, label in COLOUR_LABELS.items():
        assert label.split(":")[0].split()[0] == mode, label
        words = label.split(": ", 1)[-1] if ":" in label else label.removeprefix(mode).strip()
        for said in helps:
            assert f"{mode}: {words}" in said or (not words and mode in said), (mode, said)
