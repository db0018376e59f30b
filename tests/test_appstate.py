"""The Qt-free application state, and the rule that the core never imports Qt."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from tonguevis.appstate import MAX_SPEED, MIN_SPEED, AppState, connected, interval_at


def recorder(state: AppState, *names: str) -> list:
    events: list = []
    for name in names:
        getattr(state.events, name).connect(events.append)
    return events


def test_set_time_clamps_and_notifies_once():
    state = AppState(0.0, 2.0, 0.01)
    events = recorder(state, "time")
    state.set_time(1.234, source="plot")
    state.set_time(1.234)  # unchanged: no event
    state.set_time(5.0)
    state.set_time(-1.0)
    assert [e.value for e in events] == [1.234, 2.0, 0.0]
    assert events[0].source == "plot"
    assert state.time == 0.0


def test_nan_time_is_ignored():
    state = AppState(0.0, 1.0)
    state.set_time(0.5)
    state.set_time(float("nan"))
    assert state.time == 0.5


def test_step_snaps_to_frame_grid():
    state = AppState(1.0, 2.0, 0.01)
    state.set_time(1.2349)
    state.step(1)
    assert state.time == pytest.approx(1.24)
    state.step(-3)
    assert state.time == pytest.approx(1.21)
    state.step(-1000)
    assert state.time == 1.0


def test_speed_is_clamped_to_quarter_to_real_time():
    state = AppState()
    events = recorder(state, "speed")
    state.set_speed(0.1)
    state.set_speed(3.0)
    state.set_speed(0.5)
    assert [e.value for e in events] == [MIN_SPEED, MAX_SPEED, 0.5]


def test_playing_events_only_on_change():
    state = AppState()
    events = recorder(state, "playing")
    state.set_playing(True)
    state.set_playing(True)
    state.toggle_playing()
    assert [e.value for e in events] == [True, False]


def test_loop_range_clamped_sorted_and_used_as_playback_bounds():
    state = AppState(0.0, 10.0)
    state.set_loop((4.0, 2.0))
    assert state.loop == (2.0, 4.0)
    assert state.playback_bounds() == (2.0, 4.0)
    state.set_loop((9.0, 20.0))
    assert state.loop == (9.0, 10.0)
    state.set_loop((3.0, 3.0))  # empty: no loop
    assert state.loop is None
    assert state.playback_bounds() == (0.0, 10.0)


def test_new_range_clears_loop_and_clamps_time():
    state = AppState(0.0, 10.0)
    state.set_time(8.0)
    state.set_loop((1.0, 2.0))
    events = recorder(state, "range", "time")
    state.set_range(0.0, 5.0, 0.02)
    assert state.loop is None
    assert state.time == 5.0
    assert [e.name for e in events] == ["range", "time"]
    with pytest.raises(ValueError):
        state.set_range(3.0, 1.0, 0.01)
    with pytest.raises(ValueError):
        state.set_range(0.0, 1.0, 0.0)


def test_unsubscribe_and_unknown_event():
    state = AppState(0.0, 1.0)
    seen = []
    unsubscribe = connected(state.events.time, seen.append)
    state.set_time(0.3)
    unsubscribe()
    state.set_time(0.4)
    assert len(seen) == 1
    with pytest.raises(AttributeError, match="tiem"):  # typed events: a misspelt name fails at once
        state.events.tiem.connect(seen.append)


def test_observer_writing_back_does_not_recurse_forever():
    # A view that snaps the time to its own frame grid writes back inside the
    # callback; the second event carries the snapped value and then it settles.
    state = AppState(0.0, 1.0, 0.1)
    seen = []

    def snapping_view(event):
        seen.append(event.value)
        state.set_time(round(event.value, 1))

    state.events.time.connect(snapping_view)
    state.set_time(0.33)
    assert seen == [0.33, 0.3]
    assert state.time == 0.3


def test_selection_and_colour():
    state = AppState()
    events = recorder(state, "selection", "color")
    state.select("TT")
    state.set_color("energy")
    with pytest.raises(ValueError):
        state.set_color("rainbow")
    assert [(e.name, e.value) for e in events] == [("selection", "TT"), ("color", "energy")]


def test_frame_of_reference_is_head_by_default_and_checked():
    from tonguevis.appstate import REFERENCE_FRAMES
    from tonguevis.sim.reference import REFERENCE_FRAMES as CORE_FRAMES

    assert REFERENCE_FRAMES == CORE_FRAMES  # the app offers the frames the core knows
    state = AppState()
    events = recorder(state, "reference")
    assert state.reference == "head"
    state.set_reference("jaw", source="menu")
    state.set_reference("jaw")  # unchanged: no event
    with pytest.raises(ValueError, match="head, jaw"):
        state.set_reference("skull")
    assert [(e.value, e.source) for e in events] == [("jaw", "menu")] and state.reference == "jaw"


def test_the_commands_offer_the_apps_colourings():
    from tonguevis.appstate import COLOR_MODES
    from tonguevis.cli.view import COLOR_CHOICES

    assert COLOR_CHOICES == COLOR_MODES


def test_interval_at():
    intervals = [(0.0, 1.0), (1.5, 2.0)]
    assert interval_at(intervals, 1.7) == (1.5, 2.0)
    assert interval_at(intervals, 1.2) is None



# -- the app model: sessions, motions, morph ends, the tongue model, status ------------------------------

class _Session:
    """A stand-in for gui.session.Session: the model only holds and hands it on."""

    def __init__(self, name):
        self.name, self.motion = name, None


def test_sessions_open_in_roles_and_the_primary_one_is_the_session():
    from tonguevis.appstate import SESSION_ROLES

    assert SESSION_ROLES == ("primary", "compare")
    state = AppState()
    events = recorder(state, "session")
    a, b = _Session("a"), _Session("b")
    state.set_session(a, source="window")
    state.set_session(b, role="compare")
    assert state.session is a and state.session_of("compare") is b
    assert state.sessions == {"primary": a, "compare": b}
    assert [(e.key, e.value.name, e.source) for e in events] == [("primary", "a", "window"), ("compare", "b", None)]
    state.set_session(None, role="compare")  # closed
    state.set_session(None, role="compare")  # already closed: no event
    assert state.sessions == {"primary": a} and events[-1].key == "compare" and events[-1].value is None
    assert len(events) == 3
    with pytest.raises(ValueError, match="primary, compare"):
        state.set_session(a, role="third")


def test_a_motion_event_only_for_a_session_still_open():
    state = AppState()
    events = recorder(state, "motion")
    old, new = _Session("old"), _Session("new")
    state.set_session(old)
    state.set_session(new)  # a newer recording opened while the old one simulated
    assert state.set_motion(old) is None  # the old one's results arrive late: nobody hears them
    assert state.set_motion(new, source="job") == "primary"
    assert [(e.key, e.value, e.source) for e in events] == [("primary", new, "job")]


def test_follow_session_hears_opening_and_motion_of_its_role_only():
    state = AppState()
    primary, compare = [], []
    stop = state.follow_session(primary.append)
    state.follow_session(compare.append, role="compare")
    a, b = _Session("a"), _Session("b")
    state.set_session(a)
    state.set_session(b, role="compare")
    state.set_motion(a)
    assert primary == [a, a] and compare == [b]
    stop()
    state.set_session(b)
    assert primary == [a, a]


def test_motions_are_added_by_name_and_sent_whole():
    state = AppState()
    events = recorder(state, "motions")
    state.add_motions({"spk1_ta": "m1"})
    state.add_motions({})  # nothing new: no event
    state.add_motions({"spk2_ka": "m2", "spk1_ta": "m1b"})
    assert [e.value for e in events] == [{"spk1_ta": "m1"}, {"spk1_ta": "m1b", "spk2_ka": "m2"}]
    events[-1].value.clear()  # a listener cannot change the model by changing what it got
    assert state.motions == {"spk1_ta": "m1b", "spk2_ka": "m2"}


def test_morph_ends_keyed_by_end_and_checked():
    state = AppState()
    events = recorder(state, "morph_ends")
    assert state.morph_ends == {"source": None, "target": None}
    state.set_morph_end("target", "spk1_la", 5.04, source="energy")
    assert state.morph_ends == {"source": None, "target": ("spk1_la", 5.04)}
    assert [(e.key, e.value, e.source) for e in events] == [("target", ("spk1_la", 5.04), "energy")]
    with pytest.raises(ValueError, match="source, target"):
        state.set_morph_end("middle", "spk1_la", 1.0)
    with pytest.raises(ValueError, match="finite"):
        state.set_morph_end("source", "spk1_la", float("nan"))


def test_tongue_model_and_status():
    state = AppState()
    events = recorder(state, "tongue_model", "status")
    assert state.tongue_model is None and state.mesh_path is None
    state.set_tongue_model("model", mesh_path="tongue.vtu")
    state.set_status("simulating")
    state.set_status("simulating")  # repeated: sent again (the bar may show another message meanwhile)
    assert state.tongue_model == "model" and state.mesh_path == "tongue.vtu" and state.status == "simulating"
    assert [(e.name, e.value) for e in events] == [("tongue_model", "model"), ("status", "simulating"),
                                                  ("status", "simulating")]


#: Top-level packages of Qt and its Python bindings that no core module may import.
QT_PACKAGES = ("PySide6", "PySide2", "PyQt5", "PyQt6", "pyvistaqt", "qtpy")


def test_core_never_imports_qt():
    """Every non-GUI module imports with Qt made unimportable, and none of them reaches for it.

    As on a headless install without PySide6, importing any Qt package raises;
    each attempt is recorded with the tonguevis module that made it.  A core
    module failing to import for any reason fails the test (it could not be
    checked otherwise), and the modules are listed from the files on disk, so
    none is skipped because its package failed to import.
    """
    code = textwrap.dedent(
        f"""
        import importlib, importlib.abc, json, pathlib, sys, traceback

        QT = {QT_PACKAGES!r}
        attempts = []

        class BlockQt(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in QT:
                    frame, culprit = sys._getframe(1), "?"
                    while frame is not None:
                        module = frame.f_globals.get("__name__", "")
                        if module.startswith("tonguevis"):
                            culprit = module
                            break
                        frame = frame.f_back
                    attempts.append([culprit, name])
                    raise ModuleNotFoundError(f"Qt is blocked in this test: {{name}}", name=name)
                return None

        sys.meta_path.insert(0, BlockQt())
        import tonguevis

        root = pathlib.Path(tonguevis.__file__).parent
        core = []
        for path in sorted(root.rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[0] == "gui" or parts == ["__main__"]:
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            core.append(".".join(["tonguevis", *parts]))
        failed = {{}}
        for name in core:
            try:
                importlib.import_module(name)
            except Exception:
                failed[name] = traceback.format_exc(limit=-2)
        loaded = sorted(m for m in sys.modules if m.split(".")[0] in QT)
        print(json.dumps({{"core": core, "failed": failed, "attempts": attempts, "loaded": loaded}}))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["attempts"] == [], f"core modules importing Qt (module, Qt package): {report['attempts']}"
    assert report["failed"] == {}, "core modules that do not import:\n" + "\n".join(
        f"{name}:\n{tb}" for name, tb in report["failed"].items())
    assert report["loaded"] == []
    # the walk really covered the core: the state, the commands, every science package
    expected = {"tonguevis.appstate", "tonguevis.cli.view", "tonguevis.io.ndi_wave", "tonguevis.sim.curl",
                "tonguevis.preprocess.alignment", "tonguevis.analysis.energy", "tonguevis.mesh.landmarks"}
    assert expected <= set(report["core"]), expected - set(report["core"])
    assert not any(name.startswith("tonguevis.gui") for name in report["core"])
