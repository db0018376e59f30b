"""The live session without Qt (issue 34): the demo streamed into it frame by frame takes its rest, simulates
as a LiveSimulator does, counts, places and scores targets, records sweeps, low-passes the display, and says
all of it in events; the app's model holds it."""

from __future__ import annotations

import subprocess
import sys
import time
from collections import deque

import numpy as np
import pytest

from tonguevis.live.session import MAX_BURST, LiveSession
from tonguevis.live.simulator import LiveSimulator
from tonguevis.live.source import LiveFrame, Source, SourceStatus, recording_frames
from tonguevis.paths import DEMO_RECORDING
from tonguevis.sim.settings import RunSettings

SETTINGS = RunSettings(modes=20)  # a few modes: the session's logic, not the physics, is tested here


@pytest.fixture(scope="module")
def demo():
    """(slot names, [LiveFrame] of the demo as a stream carries it: mm, float32 values, at 100 Hz)."""
    from tonguevis.workflows import open_recording

    recording = open_recording(DEMO_RECORDING, audio=False, labels=False)
    positions, quaternions, times = recording_frames(recording)
    frames = [LiveFrame(i + 1, float(times[i]), time.perf_counter(), positions[i], quaternions[i],
                        np.zeros(len(positions[i]))) for i in range(len(times))]
    return list(recording.sensor_names), frames


class ListSource(Source):
    """A source whose frames the test hands it (:meth:`push`); :meth:`get` gives them in order."""

    def __init__(self, names):
        self.sensor_names = list(names)
        self.pending: deque = deque()
        self.started = self.closed = False

    def push(self, frames) -> None:
        self.pending.extend(frames)

    def start(self):
        self.started = True
        return self

    def latest(self):
        return self.pending[-1] if self.pending else None

    def get(self, timeout=None):
        return self.pending.popleft() if self.pending else None

    def status(self):
        return SourceStatus(state="streaming")

    def close(self) -> None:
        self.closed = True


def recorder(session) -> list:
    """Every event of ``session`` as (name, value), in order."""
    seen = []
    for name in ("source", "frame_processed", "rest_changed", "targets_changed", "sweep_changed", "status",
                 "error"):
        getattr(session.events, name).connect(lambda event: seen.append((event.name, event.value)))
    return seen


def named(seen: list, name: str) -> list:
    return [value for n, value in seen if n == name]


def test_the_session_runs_in_a_script_without_qt():
    """Streamed, rested and simulated in a process that never loads Qt, pyvistaqt nor VTK."""
    script = """
import sys, time
import numpy as np
from tonguevis.live.session import LiveSession
from tonguevis.live.source import LiveFrame, recording_frames
from tonguevis.paths import DEMO_RECORDING
from tonguevis.sim.settings import RunSettings
from tonguevis.workflows import open_recording
rec = open_recording(DEMO_RECORDING, audio=False, labels=False)
pos, q, times = recording_frames(rec)
session = LiveSession(RunSettings(modes=20), sensor_names=rec.sensor_names)
for i in range(400):
    session.process([LiveFrame(i + 1, times[i], time.perf_counter(), pos[i], q[i], np.zeros(len(pos[i])))])
assert session.simulator is not None and session.latest.surface.shape == (len(session.simulator.surface_nodes), 3)
print(sorted({m.split(".")[0] for m in sys.modules} & {"PySide6", "pyvistaqt", "vtk", "vtkmodules", "pyvista"}))
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"


def test_the_rest_is_the_stillest_half_second_and_the_frames_are_the_simulators(demo):
    names, frames = demo
    session = LiveSession(SETTINGS)
    seen = recorder(session)
    source = ListSource(names)
    assert session.set_source(source) and source.started
    assert named(seen, "source") == [source]
    assert session.tick() is None and named(seen, "frame_processed") == []  # nothing came: nothing said
    # One frame a tick until the first 3 s are seen: the rest is then taken by itself, once.
    k = 0
    while session.simulator is None:
        source.push(frames[k:k + 1])
        session.tick()
        k += 1
    assert k == 301 and frames[k - 1].timestamp_s - frames[0].timestamp_s == pytest.approx(3.0)
    rests = named(seen, "rest_changed")
    assert len(rests) == 1 and rests[0].startswith("rest (stillest moment): ") and "TT, TD, TL, TR" in rests[0]
    assert session.rest_line == rests[0] and "rest taken" in named(seen, "status")
    # The same rest as a LiveSimulator's own on the same frames.
    reference = LiveSimulator(names, SETTINGS, model=session.model, rate=session.simulator.rate)
    for frame in frames[:k]:
        reference.observe(frame.timestamp_s, frame.positions)
    reference.take_rest()
    np.testing.assert_array_equal(session.simulator.rest_times, reference.rest_times)
    reference.step(frames[k - 1].positions)  # the frame the rest was taken on is the first simulated
    # Then every frame is simulated (in ticks of several: only the newest is handed to the views) as the
    # reference simulates it; the update carries its surface with the jaw's offset, the corrected sensors.
    updates = []
    session.events.frame_processed.connect(lambda event: updates.append(event.value))
    for size in (1, 3, 7, 2, 5):
        source.push(frames[k:k + size])
        for frame in frames[k:k + size]:
            step = reference.step(frame.positions)
        k += size
        assert session.tick() is updates[-1] is session.latest
        update = updates[-1]
        assert update.frame is frames[k - 1] and update.frames == size and update.names == names
        np.testing.assert_array_equal(update.surface, step.surface + step.jaw_offset)
        np.testing.assert_array_equal(update.sensors_head, step.corrected)
        np.testing.assert_array_equal(update.sensors, reference.sensor_points_in_view(step))
        assert update.time_s == pytest.approx(frames[k - 1].timestamp_s - frames[0].timestamp_s)
    assert session.frames_received == k and session.dropped_frames == k - 301 - 5
    # Another device (a slot less): the simulation is dropped and the clinician told to take the rest again.
    fewer = frames[k]
    session.process([LiveFrame(fewer.frame, fewer.timestamp_s, fewer.arrival_s, fewer.positions[:-1],
                               fewer.quaternions[:-1], fewer.rms[:-1])])
    assert session.simulator is None and session.latest.surface is None
    assert named(seen, "rest_changed")[-1] == "the stream's sensors changed: take the rest again"
    session.close_source()
    assert source.closed and named(seen, "source")[-1] is None and session.source is None


def test_the_counters_count_what_was_received_dropped_and_skipped(demo):
    names, frames = demo
    session = LiveSession(SETTINGS, sensor_names=names, auto_rest=False)
    ticks = []
    session.events.frame_processed.connect(lambda event: ticks.append(event.value.frames))
    start = 0
    for size in (1, 4, MAX_BURST, MAX_BURST + 13, 2):
        session.process(frames[start:start + size])
        start += size
    sizes = [1, 4, MAX_BURST, MAX_BURST + 13, 2]
    assert ticks == [min(n, MAX_BURST) for n in sizes]
    assert session.frames_received == sum(sizes)
    assert session.skipped_frames == 13  # the burst's oldest ones: not even simulated
    assert session.dropped_frames == sum(min(n, MAX_BURST) - 1 for n in sizes)  # simulated, not the newest
    assert session.latest.frame is frames[start - 1]
    session.reset_counters()
    assert (session.frames_received, session.dropped_frames, session.skipped_frames) == (0, 0, 0)


def test_the_display_low_pass_is_first_order_and_leaves_what_is_saved_raw(demo):
    names, frames = demo
    session = LiveSession(SETTINGS, sensor_names=names, auto_rest=False)
    raw = np.stack([f.positions for f in frames[:40]]) / 1000.0
    raw[10:14, 2] = np.nan  # a sensor lost for a while: drawn again as soon as it is back
    frames = [LiveFrame(f.frame, f.timestamp_s, f.arrival_s, raw[i] * 1000.0, f.quaternions, f.rms)
              for i, f in enumerate(frames[:40])]
    tau = 0.05
    session.set_smoothing(tau)
    drawn = [session.process([frame]).sensors.copy() for frame in frames]
    # The reference: y0 = x0, then y += (1 - exp(-dt / tau)) (x - y) where y is known, else y = x.
    y = raw[0].copy()
    np.testing.assert_array_equal(drawn[0], y)
    for i in range(1, len(frames)):
        alpha = 1.0 - np.exp(-(frames[i].timestamp_s - frames[i - 1].timestamp_s) / tau)
        y = np.where(np.isfinite(y), y + alpha * (raw[i] - y), raw[i])
        np.testing.assert_allclose(drawn[i], y, rtol=0, atol=1e-15, equal_nan=True)
    assert np.abs(drawn[-1] - raw[-1])[np.isfinite(raw[-1])].max() > 1e-5  # it lags: it smooths
    session.set_smoothing(0)
    np.testing.assert_array_equal(session.process([frames[0]]).sensors, raw[0])


def test_targets_are_placed_scored_and_fixed_during_a_sweep_which_is_saved(demo, tmp_path):
    from tonguevis.live.targets import accuracy_percent
    from tonguevis.workflows import open_recording

    names, frames = demo
    session = LiveSession(SETTINGS, sensor_names=names, auto_rest=False, profiles_root=tmp_path / "profiles")
    seen = recorder(session)
    session.add_static_target(0.004)  # no frame yet: said, nothing placed
    assert session.targets == [] and named(seen, "targets_changed") == []
    assert "no frame yet" in named(seen, "status")[-1]
    for frame in frames[:10]:
        session.process([frame])
    session.add_static_target(0.004)
    changed = named(seen, "targets_changed")
    assert len(changed) == 1 and changed[0] == session.targets == session.profile.targets
    tip = frames[9].positions[names.index("TT")] / 1000.0  # the tip now (no simulation: the stream's position)
    np.testing.assert_array_equal(session.targets[0].point, tip)
    update = session.process([frames[10]])
    centre, accuracy = update.targets[0]
    np.testing.assert_array_equal(centre, tip)
    distance = np.linalg.norm(frames[10].positions[names.index("TT")] / 1000.0 - tip)
    assert accuracy == session.accuracy[0] == pytest.approx(float(accuracy_percent(distance, 0.004)))
    # A sweep: the targets are fixed while it records; every frame is saved.
    assert session.start_sweep("ta")
    assert named(seen, "sweep_changed")[-1].startswith("recording sweep")
    session.remove_target(0)
    assert len(session.targets) == 1 and "fixed during a sweep" in named(seen, "status")[-1]
    for frame in frames[11:31]:
        session.process([frame])
    saved = session.stop_sweep()
    assert saved is not None and session.sweep is None and "saved in" in named(seen, "sweep_changed")[-1]
    assert saved.folder.parent == tmp_path / "profiles" / "default" / "sweeps"
    assert open_recording(saved.folder / "raw.tsv").n_samples == 20
    session.remove_target(0)
    assert session.targets == [] and named(seen, "targets_changed")[-1] == []


def test_a_rest_that_cannot_be_taken_is_said_not_raised(demo):
    names, frames = demo
    session = LiveSession(SETTINGS.replace(rest=(0.0, 0.005)), sensor_names=names)
    seen = recorder(session)
    assert not session.take_rest_now() and named(seen, "status") == ["no frames yet to take the rest from"]
    for frame in frames[:5]:
        session.process([frame])
    # The given rest holds one frame: refused once, and the session stops trying by itself.
    rests = named(seen, "rest_changed")
    assert len(rests) == 1 and rests[0].startswith("no rest: the rest 0-0.005 s (--rest) holds 1 frame(s)")
    assert session.simulator is None and not session.auto_rest
    assert session.take_rest_now() and session.simulator is not None  # the last frames, on request
    assert named(seen, "rest_changed")[-1].startswith("rest taken: ")


def test_the_app_model_holds_the_live_session():
    from tonguevis.appstate import AppState

    state = AppState()
    heard = []
    state.events.live_session.connect(lambda event: heard.append(event.value))
    session = LiveSession(SETTINGS, auto_rest=False)
    state.set_live_session(session)
    state.set_live_session(session)  # the same one again: nothing new
    assert state.live_session is session and heard == [session]
    state.set_live_session(None)
    assert state.live_session is None and heard == [session, None]


def test_the_readme_runs_a_live_session_from_a_script(monkeypatch, tmp_path, capsys):
    """The README's snippet, as written: the demo played in-process into a session, its rest said."""
    import re

    from tonguevis.paths import REPO_DIR

    readme = (REPO_DIR / "README.md").read_text(encoding="utf-8")
    blocks = [b for b in re.findall(r"```python\n(.*?)```", readme, flags=re.S) if "LiveSession()" in b]
    assert len(blocks) == 1, "the README shows a live session run from a script"
    monkeypatch.setenv("TONGUEVIS_PROFILES", str(tmp_path))
    monkeypatch.chdir(REPO_DIR)
    exec(compile(blocks[0], "README.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("rest (stillest moment): ")
    shape, received, dropped = re.fullmatch(r"\((\d+), 3\) (\d+) (\d+)", lines[-1]).groups()
    assert int(shape) > 500 and int(received) >= 600 and 0 <= int(dropped) < int(received)


def test_the_velum_lifts_live_with_the_dorsum_as_the_replay_lifts_it(osn12_palate):
    """Issue 36 (items 1 and 6): live with the speaker's palate, the velum is lifted frame by frame by the least
    lift keeping the dorsum sensors over the soft palate a coil's half under it (the replay's rule), held over the
    last frames; the palatogram is measured against the palate as lifted then.  On the real /ka/ 006: it lifts."""
    from tests.conftest import shared_file
    from tonguevis.analysis.epg import electrode_contacts
    from tonguevis.sim.speaker_palate import LIFT_HOLD, velum_lift
    from tonguevis.workflows import open_recording

    recording = open_recording(shared_file("ema", "optispeech", "006_OSN12_Kah_nofb_natural_take2_HR.tsv"),
                               audio=False, labels=False)
    positions, quaternions, times = recording_frames(recording)
    session = LiveSession(RunSettings(modes=40, palate=str(osn12_palate)), sensor_names=recording.sensor_names)
    sim, lifts, own = None, [], []
    contacts_checked = 0
    for i in range(min(len(times), 900)):  # the rest, then the first /k/ closures
        update = session.process([LiveFrame(i + 1, float(times[i]), time.perf_counter(), positions[i],
                                            quaternions[i], np.zeros(len(positions[i])))])
        if update.step is None:
            continue
        sim = session.simulator
        assert session.velum is not None and sim.palate.lift_shape is not None  # the speaker's palate: it lifts
        own.append(float(velum_lift(sim.palate, sim.sensor_points_in_view(update.step)[None])[0]))
        lifts.append(update.velum_lift)
        assert update.velum_lift == pytest.approx(max(own[-(LIFT_HOLD + 1):]), abs=1e-12)
        if update.velum_lift > 0 and contacts_checked < 3:
            session.epg.last_s = -np.inf  # due now
            got = session.palatogram(update)
            surface = (np.asarray(update.step.surface, dtype=np.float64) + update.step.jaw_offset)[session.epg.index]
            want = electrode_contacts(surface[None], session.epg.triangles, sim.palate.lifted(update.velum_lift),
                                      session.epg.layout)[0]
            assert np.array_equal(got, want)
            contacts_checked += 1
    assert sim is not None and len(lifts) > 100
    assert max(lifts) > 0.5e-3 and contacts_checked == 3  # the dorsum lifts the velum at the /k/ closures
    assert min(lifts) == 0.0  # and it comes down again


def test_a_model_that_stops_following_the_sensors_is_said_and_a_new_rest_clears_it(demo):
    """The shared /ta/ 009 streamed, its rest taken by itself in the jaw's opening before speech (0.06-0.56 s):
    from 5 s on the model cannot follow most frames (the replay refuses that rest: 591 frames recovered).  The
    session says so once, on the rest's line and the status bar, with what to do; a new rest clears it.  The
    demo, on its own rest, is followed throughout and nothing is said."""
    from tests.conftest import shared_file
    from tonguevis.workflows import open_recording

    recording = open_recording(shared_file("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv"),
                               audio=False, labels=False)
    positions, quaternions, times = recording_frames(recording)
    session = LiveSession(RunSettings(), sensor_names=recording.sensor_names)
    said = recorder(session)
    recovered = 0
    for i in range(len(times)):
        update = session.process([LiveFrame(i + 1, float(times[i]), time.perf_counter(), positions[i],
                                            quaternions[i], np.zeros(len(positions[i])))])
        recovered += bool(update.step is not None and update.step.recovered)
    warnings = [s for s in named(said, "status") if "not following" in s]
    assert recovered > 300 and len(warnings) == 1
    assert 4.5 < session.not_following_since < 6.0
    assert "take the rest again at a still moment" in warnings[0]
    assert session.rest_line.startswith("rest (stillest moment): 0.06-0.56 s") and "not following" in session.rest_line
    assert session.take_rest_now() and session.not_following_since is None
    assert "not following" not in session.rest_line

    names, frames = demo
    quiet = LiveSession(SETTINGS, sensor_names=names)
    heard = recorder(quiet)
    for frame in frames[:800]:
        quiet.process([frame])
    assert quiet.simulator is not None and quiet.not_following_since is None
    assert not [s for s in named(heard, "status") if "not following" in s]
