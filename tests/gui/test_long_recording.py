"""The app on a long recording: frames made from q when shown, a bounded cache, no full pass."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("PySide6")
pytest.importorskip("pyvistaqt")

from tests.gui.conftest import DEMO, show_and_simulate  # noqa: E402

pytestmark = [pytest.mark.gui, pytest.mark.timeout(300)]


def tiled_session(minutes: float):
    """The demo /ta/ repeated to ``minutes`` (sensors, orientations and sound), as the app opens it."""
    from tonguevis.workflows.session import load_session, make_session

    if not DEMO.exists():
        pytest.skip(f"demo corpus not built: {DEMO}")
    rec = load_session(DEMO).recording
    n = rec.n_samples
    copies = int(np.ceil(minutes * 60 * rec.rate / n))
    period = n / rec.rate
    times = np.concatenate([rec.times + k * period for k in range(copies)])
    audio = rec.audio
    if audio is not None:
        per_copy = int(round(period * audio.rate))
        samples = np.resize(np.asarray(audio.samples)[:per_copy], per_copy * copies)
        audio = replace(audio, samples=samples)
    tiled = replace(rec, times=times, sensors={k: np.tile(v, (copies, 1)) for k, v in rec.sensors.items()},
                    orientations={k: np.tile(v, (copies, 1)) for k, v in rec.orientations.items()}, audio=audio)
    return make_session(tiled, DEMO)


def test_a_two_minute_recording_opens_without_precomputing_every_frame(qtbot, window):
    from tonguevis.render.frames import CACHE_FRAMES, COLOUR_FRAMES

    session = show_and_simulate(qtbot, window, tiled_session(2.0), timeout=240000)
    frames = session.frames
    assert frames.n_frames >= 12000
    # Opening drew one frame: only its block was made.
    assert 0 < frames.cached_frames <= frames.block
    state, view = window.state, window.view3d
    rng = np.random.default_rng(0)
    for mode in ("displacement", "energy", "plain"):
        state.set_color(mode)
        for t in np.concatenate([state.time + 0.01 * np.arange(1, 60), rng.uniform(state.start, state.end, 30)]):
            state.set_time(float(t))
            i = frames.frame_at(state.time)
            assert view.frame == i
            assert frames.cached_frames <= CACHE_FRAMES < frames.n_frames
    # What the view drew is the motion's own frame, reconstructed from q.
    model, motion = session.motion.model, session.motion
    u = motion.displacement(i)
    drawn = frames.nodes
    assert np.allclose(frames.points[i][drawn], (model.mesh.points + u)[drawn], atol=1e-6)
    assert len(drawn) < model.mesh.n_nodes  # the surface only: the inside is not drawn
    assert COLOUR_FRAMES < frames.n_frames and frames.clim["displacement"][1] > 0


def test_a_long_recording_shows_its_first_seconds_while_the_rest_simulates(qtbot, window):
    """The first 20 s are drawn as soon as they are simulated (same frames as the whole motion), the
    progress dialog gives the window back, the Energy tab waits for the whole motion."""
    from tonguevis.gui.tabs import add_feature_tabs

    add_feature_tabs(window)
    seen, ranges = [], []

    def on_motion(event):
        session = event.value
        seen.append((session.motion, window.view3d.renders, window.state.end))
        ranges.append(dict(session.frames.clim))

    window.state.events.motion.connect(on_motion)
    energy_motions = []
    window.energy_tab.motionsLoaded.connect(lambda motions: energy_motions.append(dict(motions)))
    session = show_and_simulate(qtbot, window, tiled_session(1.0), timeout=240000)
    assert len(seen) == 2
    (preview, painted_before, _), (whole, painted_after, end) = seen
    n = preview.n_frames
    assert preview.metadata["preview"] == {"frames": n, "of": whole.n_frames}
    assert 2000 <= n < whole.n_frames and "preview" not in whole.metadata
    np.testing.assert_array_equal(preview.q, whole.q[:n])
    np.testing.assert_array_equal(preview.volume_change, whole.volume_change[:n])
    assert painted_before > 0  # the preview was drawn (nothing is before a motion) before the whole came
    assert end == pytest.approx(whole.times[-1])  # the time range grew to the whole recording
    assert session.motion is whole and session.frames.n_frames == whole.n_frames
    assert window.worker.dialog is None  # closed at the preview: the window was usable from then on
    assert energy_motions and all(m is whole for batch in energy_motions for m in batch.values())
    # the preview's colour ranges from a small sample of its frames, the whole motion's from its own
    from tonguevis.render.frames import MotionFrames
    from tonguevis.workflows.simulation import PREVIEW_COLOUR_FRAMES

    assert ranges[0] == MotionFrames(preview, colour_frames=PREVIEW_COLOUR_FRAMES).clim != \
        MotionFrames(preview).clim
    assert ranges[1] == session.frames.clim
