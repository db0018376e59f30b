"""Build the tongue model and simulate a session (no Qt; the job runner's thread runs this).

:func:`simulate_motion` only *returns* what it made (a :class:`Simulated`): the model
it built or was given, the motion, its drawing frames and the palate shown.  The GUI
thread then sets them on the session (:meth:`Simulated.apply`); nothing shared is
assigned from the worker thread.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tonguevis._progress import ProgressCallback
from tonguevis.gui.frames import MotionFrames
from tonguevis.gui.session import Session

log = logging.getLogger("tonguevis")

#: Frames sampled for the colour ranges of a preview (the whole motion samples up to frames.COLOUR_FRAMES).
PREVIEW_COLOUR_FRAMES = 200


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


@dataclass
class Simulated:
    """What one simulation made: the ``model`` it ran on, the ``motion``, its drawing ``frames``, the
    ``palate`` it was simulated against (None: no contact) and the ``shown_palate`` the views draw."""

    model: Any
    motion: Any
    frames: Any
    palate: Any = None
    shown_palate: Any = None

    def apply(self, session: Session) -> Session:
        """Set the results on ``session`` (on the thread that owns it: the GUI thread in the app)."""
        session.set_motion(self.motion, self.frames, self.palate, self.shown_palate)
        return session


def simulate_motion(
    recording,
    given_rest: tuple[float, float] | None = None,
    model=None,
    mesh_path: str | os.PathLike | None = None,
    modes: int = 100,
    warping: bool = True,
    landmarks: str = "speaker",
    progress: ProgressCallback | None = None,
    palate=None,
    preview=None,
    sensor_patches=None,
) -> Simulated:
    """Simulate ``recording`` on ``model`` (None: built from ``mesh_path``); returns a :class:`Simulated`.

    ``palate`` (a PalateSurface, a palate file or "generic"; None: no contact): the tongue is kept
    below it; the :attr:`Simulated.shown_palate` is it placed in the model frame as the simulation
    placed it (without one, the generic palate, drawn only).  The rest is ``given_rest`` when the
    user gave one, else found as every front end finds it (:func:`tonguevis.workflows.simulate_recording`).
    ``landmarks``: sensor nodes snapped to the speaker's layout ('speaker') or the paper's placement
    rule ('rule').  ``sensor_patches`` as :func:`tonguevis.simulate` (None: the modes alone).
    ``progress(done, total, message)`` may raise :class:`tonguevis.errors.Cancelled`.
    ``preview(simulated)``: called once, on this thread, with a :class:`Simulated` of the recording's first
    seconds as soon as they are final (:func:`tonguevis.sim.simulate`'s preview; a long recording is shown
    while the rest simulates; not called for a short one, nor with a palate).
    """
    from tonguevis.workflows import simulate_recording

    if progress is not None:
        progress(0, 1000, "building the tongue model")
    if model is None:
        model = build_model(mesh_path)
    options = {} if palate is None else {"palate": palate}
    if sensor_patches is not None:
        options["sensor_patches"] = sensor_patches
    if preview is not None:
        def first_seconds(motion) -> None:
            # Colour ranges from a sample of the first seconds: the whole motion brings its own.
            preview(Simulated(model, motion, MotionFrames(motion, colour_frames=PREVIEW_COLOUR_FRAMES), palate,
                              shown_palate(recording, motion, model, palate)))

        options["preview"] = first_seconds
    motion = simulate_recording(recording, model, modes=modes, warping=warping, landmarks=landmarks,
                                rest=given_rest, progress=staged(progress, 0, 2, "simulating"), **options)
    shown = shown_palate(recording, motion, model, palate)
    frames = MotionFrames(motion, progress=staged(progress, 1, 2, "reconstructing frames"))
    return Simulated(model, motion, frames, palate, shown)


def simulate_session(session: Session, **options) -> Session:
    """Simulate ``session.recording`` with :func:`simulate_motion` (its ``options``: model, mesh_path,
    modes, warping, landmarks, progress, palate; the rest ``session.given_rest``) and return the session
    with ``motion``, ``frames``, ``rest`` and the palates set (for scripts, the CLI and tests on one
    thread; the app sets them on the GUI thread instead)."""
    return simulate_motion(session.recording, session.given_rest, **options).apply(session)


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
    if getattr(motion, "palate", None) is not None:  # as the simulation placed it: no second preparation
        placed, raised = motion.palate, 1e-3 * motion.metadata.get("contact", {}).get("palate_raised_mm", 0.0)
    else:  # a motion loaded from a file
        placed, raised = placed_palate(recording, surface, model, landmarks=motion.metadata.get("landmarks", "speaker"),
                                       rest_interval=rest_of(motion))
    return speaker_palate(placed, palate_label(surface), simulated=True, raised_mm=1e3 * raised)
