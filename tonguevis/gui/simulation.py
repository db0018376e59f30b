"""Build the tongue model and simulate a session (no Qt; the worker thread runs this)."""

from __future__ import annotations

import logging
import os
from pathlib import Path

from tonguevis._progress import ProgressCallback
from tonguevis.gui.frames import MotionFrames
from tonguevis.gui.session import Session

log = logging.getLogger("tonguevis")


def build_model(mesh_path: str | os.PathLike | None = None):
    """The default tongue model, or one on the mesh at ``mesh_path``."""
    from tonguevis import TongueModel

    if mesh_path is None:
        return TongueModel.default()
    from_file = getattr(TongueModel, "from_file", None)
    if from_file is not None:
        return from_file(Path(mesh_path))
    from tonguevis.mesh import read_mesh

    return TongueModel.from_mesh(read_mesh(Path(mesh_path)))


def staged(progress: ProgressCallback | None, stage: int, stages: int, name: str) -> ProgressCallback | None:
    """A progress callback mapping one stage's (done, total) into a 0..1000 overall scale."""
    if progress is None:
        return None

    def callback(done: int, total: int, message: str = "") -> None:
        fraction = (done / total) if total else 0.0
        progress(int(1000 * (stage + min(max(fraction, 0.0), 1.0)) / stages), 1000, message or name)

    return callback


def simulate_session(
    session: Session,
    model=None,
    mesh_path: str | os.PathLike | None = None,
    modes: int = 100,
    warping: bool = True,
    landmarks: str = "speaker",
    progress: ProgressCallback | None = None,
    palate=None,
) -> Session:
    """Simulate ``session.recording`` and return the session with ``motion``, ``frames`` and ``rest``.

    ``palate`` (a PalateSurface, a palate file or "generic"; None: no contact): the tongue is kept
    below it, and ``session.shown_palate`` is it placed in the model frame as the simulation
    placed it (without one, the generic palate, drawn only).

    The rest is ``session.given_rest`` when the user gave one, else found as every
    front end finds it (:func:`tonguevis.workflows.simulate_recording`); ``session.rest``
    says which.  ``landmarks``: sensor nodes snapped to the speaker's layout ('speaker') or the
    paper's placement rule ('rule').  ``progress(done, total, message)`` may raise :class:`tonguevis.errors.Cancelled`.
    """
    from tonguevis.workflows import simulate_recording

    if progress is not None:
        progress(0, 1000, "building the tongue model")
    if model is None:
        model = build_model(mesh_path)
    options = {} if palate is None else {"palate": palate}
    motion = simulate_recording(session.recording, model, modes=modes, warping=warping, landmarks=landmarks,
                                rest=session.given_rest, progress=staged(progress, 0, 2, "simulating"), **options)
    shown = shown_palate(session.recording, motion, model, palate)
    frames = MotionFrames(motion, progress=staged(progress, 1, 2, "reconstructing frames"))
    session.set_motion(motion, frames, palate, shown)
    return session


def shown_palate(recording, motion, model, palate):
    """The palate the views draw for ``motion`` (:class:`tonguevis.gui.drawing.ShownPalate`), or None.

    ``palate`` as given to the simulation: placed in the model frame by the same core
    function the simulation used (:func:`tonguevis.sim.simulate.placed_palate`, with the
    motion's landmarks and rest); None: the generic palate, drawn and measured only.
    """
    from tonguevis.gui.drawing import generic_shown, palate_label, speaker_palate

    if palate is None:
        return generic_shown(simulated=False)
    from tonguevis.palate import load_palate
    from tonguevis.sim.simulate import placed_palate
    from tonguevis.workflows import rest_of

    surface = load_palate(palate)
    if surface.metadata.get("generic"):
        return generic_shown(simulated=True)
    placed, raised = placed_palate(recording, surface, model, landmarks=motion.metadata.get("landmarks", "speaker"),
                                   rest_interval=rest_of(motion))
    return speaker_palate(placed, palate_label(surface), simulated=True, raised_mm=1e3 * raised)
