"""simulate()'s frame loop in segments beside the figures (tonguevis.sim.pipeline), and its preview.

Checked against the plain way: one launch of the compiled loop over every frame, then
the figures of the whole q.
"""

from __future__ import annotations

import threading

import numpy as np
import pytest

from tonguevis.errors import Cancelled
from tonguevis.paths import DATA_DIR


@pytest.fixture(scope="module")
def demo():
    from tonguevis.io import read_recording
    from tonguevis.sim import TongueModel

    return read_recording(DATA_DIR / "spk1_ta.tsv"), TongueModel.default()


def one_launch(recording, model, motion):
    """The integration and figures as simulate() made them before: one launch, then measured whole."""
    from tonguevis.preprocess.targets import prepare_targets
    from tonguevis.sim.figures import frame_figures
    from tonguevis.sim.newmark import NewmarkSettings
    from tonguevis.sim.newmark_kernel import integrate_compiled
    from tonguevis.sim.simulate import DEFAULT_SENSOR_STIFFNESS, drive_schedule

    prep = prepare_targets(recording, model)
    basis = model.basis(motion.q.shape[1])
    dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
    s = len(prep.nodes)
    phi_s, w_s = basis.phi[dofs].reshape(s, 3, -1), model.rotation_matrix(basis)[dofs].reshape(s, 3, -1)
    targets, compliance, _ = drive_schedule(prep.displacement, recording.rate, basis.eigenvalues, phi_s,
                                            DEFAULT_SENSOR_STIFFNESS)
    settings = NewmarkSettings(dt=1.0 / recording.rate, alpha=model.material.alpha, beta=model.material.beta,
                               tolerance=1e-8, warping=True)
    result = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance, rates=False)
    return result, frame_figures(model, result.q, True, "numpy")  # float64 NumPy reconstruction


def test_segments_beside_the_figures_equal_one_launch_then_the_figures(demo, monkeypatch):
    import tonguevis.sim.pipeline as pipeline
    from tonguevis.sim import simulate

    recording, model = demo
    monkeypatch.setattr(pipeline, "SEGMENT_FRAMES", 250)  # 8 segments, the last one short
    # one_launch prepares the targets in the model frame, and runs the modes alone
    motion = simulate(recording, model, frame="model", sensor_patches=None)
    result, figures = one_launch(recording, model, motion)
    assert motion.n_frames > 7 * 250
    assert not motion.metadata["recovered_frames"]  # so q is the integration's own, frame for frame
    np.testing.assert_array_equal(motion.q, result.q)
    np.testing.assert_array_equal(motion.converged, result.converged & ~result.recovered)
    # the figures come from float32 products (see sim.figures): 1e-8 of the float64 reference
    np.testing.assert_allclose(motion.volume_change, figures.volume_change, rtol=0, atol=1e-8)
    np.testing.assert_array_equal(motion.energy, model.energy(result.q))


def test_the_preview_is_the_first_frames_of_the_whole_motion(demo, monkeypatch):
    import tonguevis.sim.pipeline as pipeline
    from tonguevis.sim import simulate

    recording, model = demo
    monkeypatch.setattr(pipeline, "SEGMENT_FRAMES", 256)
    previews = []
    motion = simulate(recording, model, preview=previews.append, preview_seconds=3.0)
    assert len(previews) == 1
    first = previews[0]
    n = first.n_frames
    assert n == 512  # 3 s at 100 Hz: the second segment's end
    assert first.metadata["preview"] == {"frames": n, "of": motion.n_frames}
    assert "preview" not in motion.metadata
    for name in ("times", "q", "energy", "volume_change", "sensor_residual", "converged", "targets", "jaw_offset"):
        np.testing.assert_array_equal(getattr(first, name), getattr(motion, name)[:n], err_msg=name)
    assert first.model is motion.model and first.sensor_names == motion.sensor_names
    # a recording shorter than a segment is whole at once: no preview
    monkeypatch.setattr(pipeline, "SEGMENT_FRAMES", 4096)
    previews.clear()
    simulate(recording, model, preview=previews.append, preview_seconds=3.0)
    assert previews == []


def test_cancelling_stops_the_frame_loop(demo, monkeypatch):
    import tonguevis.sim.pipeline as pipeline
    from tonguevis.sim import simulate

    recording, model = demo
    monkeypatch.setattr(pipeline, "SEGMENT_FRAMES", 100)
    seen = []

    def progress(done, total, message=""):
        seen.append(message)
        if "integrating and measuring" in message and len(seen) > 3:
            raise Cancelled()

    with pytest.raises(Cancelled):
        simulate(recording, model, progress=progress)
    assert not [t for t in threading.enumerate() if t.name == "tonguevis-frame-loop"]
