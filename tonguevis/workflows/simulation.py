"""Simulating a recording, as every front end does (no Qt; the app's job thread runs this too).

* :func:`simulate_recording`: :func:`tonguevis.sim.simulate` with the model first, as the workflows
  always called it; ``motion.metadata["rest"]`` says which rest was used and :func:`rest_of` gives it back.
* :func:`simulate_motion`: the same for the app and ``export-video``, returning a
  :class:`Simulated` (the model, the motion, its drawing frames and the palate shown); the GUI
  thread then sets them on the session (:meth:`Simulated.apply`): nothing shared is assigned
  from the worker thread.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from tonguevis._logging import verbose
from tonguevis._progress import ProgressCallback
from tonguevis.render.frames import MotionFrames
from tonguevis.io.recording import Recording
from tonguevis.workflows.session import Session
from tonguevis.sim.motion import rest_of  # noqa: F401 (re-exported)
from tonguevis.sim.settings import RunSettings, build_model, run_settings


#: Frames sampled for the colour ranges of a preview (the whole motion samples up to frames.COLOUR_FRAMES).
PREVIEW_COLOUR_FRAMES = 200


@verbose
def simulate_recording(recording: Recording, model=None, settings: RunSettings | None = None, *,
                       progress: ProgressCallback | None = None, **options: Any):
    """:func:`tonguevis.sim.simulate` with the model first (the workflows' order, kept for scripts):
    ``simulate(recording, settings, model, progress=progress, **options)``.  ``options`` are fields of
    :class:`RunSettings` overriding ``settings`` (``rest=`` may be a :class:`RestChoice`, used as is) and
    :func:`~tonguevis.sim.simulate`'s own keywords (``preview``...).  The choice of rest is in
    ``motion.metadata["rest"]``; :func:`rest_of` reads it back."""
    from tonguevis.sim.simulate import simulate

    return simulate(recording, settings, model, progress=progress, **options)


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


@verbose
def simulate_motion(recording, settings: RunSettings | None = None, model=None, *,
                    progress: ProgressCallback | None = None, preview=None, onto=None, **changes: Any) -> Simulated:
    """Simulate ``recording`` with ``settings`` on ``model`` (None: built from the settings); returns a
    :class:`Simulated`.  ``changes`` override fields of ``settings`` (``rest=``, ``modes=``...).

    The settings' palate (a palate file or "generic"; None: no contact) keeps the tongue below it;
    :attr:`Simulated.shown_palate` is it as the simulation placed it (without one, the generic
    palate, drawn only).  The rest is the settings' when the user gave one, else found as every
    front end finds it (:func:`simulate_recording`).
    ``progress(done, total, message)`` may raise :class:`tonguevis.errors.Cancelled`.
    ``onto``: a model placed in another speaker (e.g. recording A's, to compare): the motion is carried onto
    it and drawn there (:func:`tonguevis.sim.placement.carried`; its palate is then A's generic one).
    ``preview(simulated)``: called once, on this thread, with a :class:`Simulated` of the recording's first
    seconds as soon as they are final (:func:`tonguevis.sim.simulate`'s preview; a long recording is shown
    while the rest simulates; not called for a short one, nor with a palate).
    """
    settings = run_settings(settings, **changes)
    if progress is not None:
        progress(0, 1000, "building the tongue model")
    if model is None:
        model = build_model(settings)
    palate = settings.palate
    options = {}
    if preview is not None:
        def first_seconds(motion) -> None:
            # Colour ranges from a sample of the first seconds: the whole motion brings its own.
            preview(Simulated(model, motion, MotionFrames(motion, colour_frames=PREVIEW_COLOUR_FRAMES), palate,
                              shown_palate(recording, motion, model, palate)))

        options["preview"] = first_seconds
    motion = simulate_recording(recording, model, settings, progress=staged(progress, 0, 2, "simulating"), **options)
    if onto is not None and getattr(onto, "mesh", None) is not None:
        import numpy as np

        from tonguevis.sim.placement import carried, same_source

        if same_source(onto, motion.model) and not np.allclose(onto.mesh.points, motion.model.mesh.points):
            motion, palate = carried(motion, onto), None
    shown = shown_palate(recording, motion, model, palate)
    frames = MotionFrames(motion, progress=staged(progress, 1, 2, "reconstructing frames"))
    return Simulated(model, motion, frames, palate, shown)


def simulate_session(session: Session, settings: RunSettings | None = None, model=None, **changes: Any) -> Session:
    """Simulate ``session.recording`` with :func:`simulate_motion` (the rest: ``session.given_rest`` unless
    ``changes`` give one) and return the session with ``motion``, ``frames``, ``rest`` and the palates set
    (for scripts, the CLI and tests on one thread; the app sets them on the GUI thread instead)."""
    progress = changes.pop("progress", None)
    changes.setdefault("rest", session.given_rest)
    return simulate_motion(session.recording, settings, model, progress=progress, **changes).apply(session)


def shown_palate(recording, motion, model, palate):
    """The palate the views draw for ``motion`` (:class:`tonguevis.render.drawing.ShownPalate`), or None.

    ``palate`` as given to the simulation: placed in the motion's frame by the same core
    function the simulation used (:func:`tonguevis.sim.simulate.placed_palate`, with the
    motion's landmarks, rest, frame and tongue size); None: the generic palate (placed with
    the motion's model), drawn and measured only.
    """
    from tonguevis.render.drawing import generic_shown, palate_label, speaker_palate

    if palate is None:
        return generic_shown(simulated=False, model=motion.model)
    from tonguevis.palate import load_palate
    from tonguevis.sim.simulate import placed_palate

    surface = load_palate(palate)
    if surface.metadata.get("generic"):
        return generic_shown(simulated=True, model=motion.model)
    if getattr(motion, "palate", None) is not None:  # as the simulation placed it: no second preparation
        placed, lift = motion.palate, motion.velum_lift
    else:  # a motion loaded from a file
        fit = motion.metadata.get("fit", {})  # none: saved before the speaker frame, in the model's
        placed, lift, _ = placed_palate(recording, surface, model, landmarks=motion.metadata.get("landmarks", "speaker"),
                                        rest=rest_of(motion), frame=fit.get("frame", "model"),
                                        tongue_size=fit.get("tongue_size") if fit.get("fitted_to") == "upper surface"
                                        else None)  # placed by the alignment: its size is recorded, not asked for
        lift = motion.velum_lift if motion.velum_lift is not None else lift
    raised = motion.metadata.get("contact", {}).get("palate_raised_mm", 0.0)
    return speaker_palate(placed, palate_label(surface), simulated=True, raised_mm=raised, lift=lift)
