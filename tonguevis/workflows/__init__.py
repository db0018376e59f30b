"""Every step a front end takes, in one place: the CLI, the app, the batch and the scripts call these.

None of the front ends strings the stages together on its own (when each did, they drifted
apart).  No Qt here.

* :class:`RunSettings` (:mod:`tonguevis.sim.settings`, re-exported): one description of how a recording is
  simulated; :func:`build_model` the one way to build the tongue model from it.
* :func:`open_recording`, :func:`head_corrected`, :func:`find_recording_productions`
  (:mod:`.recording`): read a recording with its sensor map, sound and labels; its productions.
* :func:`simulate_recording`, :func:`simulate_motion`, :func:`rest_of` (:mod:`.simulation`):
  choose the rest, prepare the targets and simulate (the motion carries the placed palate).
* :class:`Session`, :func:`load_session` (:mod:`.session`): what the app has open.
* :func:`palate_from_traces` (:mod:`.palate`): the speaker's palate from trace recordings.
* :func:`~tonguevis.workflows.measures.measure_recording` (:mod:`.measures`): the productions' measures
  (constriction, kinematics) and the repetitions' STI; :mod:`.ema_wav`: the EMA as a WAV for Praat.
"""

from __future__ import annotations

from tonguevis.preprocess.rest import RestChoice, check_rest_interval, choose_rest_interval
from tonguevis.workflows.recording import (find_recording_productions, head_corrected, head_references,
                                           open_recording)
from tonguevis.sim.settings import RunSettings, build_model
from tonguevis.workflows.simulation import rest_of, simulate_recording

__all__ = [
    "RestChoice", "RunSettings", "build_model", "check_rest_interval", "choose_rest_interval",
    "find_recording_productions", "head_corrected", "head_references", "open_recording", "rest_of",
    "simulate_recording",
]
