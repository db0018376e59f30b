"""What the app has open: a recording, its productions, its simulation (no Qt).

:class:`Session` gathers the science objects the views show; the views hold
none of it themselves.  Loading and simulating are plain functions so the CLI,
the worker thread and tests share them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tonguevis._memory import release_freed_memory
from tonguevis.errors import RecordingError, TonguevisError
from tonguevis.io.recording import Recording

from tonguevis._logging import logger

#: Canonical tongue sensor names (see tonguevis.io.sensor_map); a recording
#: carrying none of them needs a sensor map before it can drive the model.
TONGUE_NAMES = ("TT", "TB", "TD", "TBK", "TL", "TR")
#: Roles offered by the sensor-mapping dialog.
ROLES = (*TONGUE_NAMES, "JAW", "UL", "LL", "REF1", "REF2", "REF3")

#: What the sensor panel can show: kind -> (label, unit, scale from SI).
SIGNAL_KINDS = {
    "position": ("position", "mm", 1e3),
    "displacement": ("displacement from rest", "mm", 1e3),
    "velocity": ("velocity", "mm/s", 1e3),
    "acceleration": ("acceleration", "mm/s²", 1e3),
}
#: Savitzky-Golay window (samples) for velocity and acceleration: plain
#: differences of 100 Hz data amplify sub-millimetre noise into spikes.
DERIVATIVE_WINDOW = 11


def needs_sensor_map(recording: Recording) -> bool:
    """True when no channel carries a canonical tongue name (TT, TB, TD, ...)."""
    return not any(name in TONGUE_NAMES for name in recording.sensor_names)


def plotted_sensors(recording: Recording) -> list[str]:
    """Every channel the sensor panel can plot: tongue sensors first (canonical order), then
    the others in the file's order, head references last.  The panel shows only the tongue
    sensors (:func:`tongue_sensors`) unless asked for the others."""
    from tonguevis.preprocess._names import is_reference

    names = recording.sensor_names
    tongue = tongue_sensors(names)
    others = [n for n in names if n not in tongue]
    return tongue + sorted(others, key=is_reference)


def tongue_sensors(names) -> list[str]:
    """The tongue sensors among ``names``, in canonical order (TT, TB, TD, TBK, TL, TR)."""
    return [n for n in TONGUE_NAMES if n in names]


def production_intervals(productions: Any) -> list[tuple[float, float]]:
    """(start_s, end_s) of each production, from objects with ``start``/``end`` or pairs."""
    out = []
    for item in productions or []:
        if hasattr(item, "start") and hasattr(item, "end"):
            out.append((float(item.start), float(item.end)))
        else:
            start, end = item[0], item[1]
            out.append((float(start), float(end)))
    return sorted(out)


def find_production_table(recording: Recording):
    """Every CV production of the recording (a ProductionTable: a ``productions`` tier of its
    TextGrid, else found), or None when none can be found (logged)."""
    from tonguevis.workflows.recording import find_recording_productions

    try:
        return find_recording_productions(recording, keep=None)
    except TonguevisError as exc:
        logger.warning("no productions found: %s", exc)
        return None


@dataclass
class Session:
    """An open recording and, once simulated, its motion.

    recording : the Recording (sensor positions in metres).
    path : where it came from (None for one built in code).
    productions : [(start_s, end_s)] CV productions, possibly empty.
    production_table : the ProductionTable they come from (None if none found).
    motion : the simulated Motion, or None until the simulation ran.
    frames : per-frame drawing data (:class:`tonguevis.render.frames.MotionFrames`).
    given_rest : (start_s, end_s) the user gave for the rest, or None to find it.
    rest : the :class:`~tonguevis.preprocess.RestChoice` the simulation used (None before).
    notes : what else the user should know about how it was simulated.
    palate : the palate the motion was simulated against (a PalateSurface or "generic"; None: no contact).
    shown_palate : the palate the views draw and measure against, in the model frame
        (:class:`tonguevis.render.drawing.ShownPalate`: ``palate`` placed as the simulation
        placed it, else the generic one drawn only), or None.
    """

    recording: Recording
    path: Path | None = None
    productions: list[tuple[float, float]] = field(default_factory=list)
    production_table: Any = None
    motion: Any = None
    frames: Any = None
    given_rest: tuple[float, float] | None = None
    rest: Any = None
    notes: list[str] = field(default_factory=list)
    palate: Any = None
    shown_palate: Any = None
    _signals: dict = field(default_factory=dict, repr=False)

    @property
    def name(self) -> str:
        return self.path.name if self.path is not None else "recording"

    @property
    def time_range(self) -> tuple[float, float, float]:
        """(start_s, end_s, frame_period_s) of the motion, else of the recording."""
        times = self.motion.times if self.motion is not None else self.recording.times
        if len(times) == 0:
            raise RecordingError("the recording has no samples", self.path)
        period = float(np.median(np.diff(times))) if len(times) > 1 else 1.0 / self.recording.rate
        return float(times[0]), float(times[-1]), period

    def set_production_table(self, table) -> None:
        """Its productions are now ``table`` (a ProductionTable, or None)."""
        self.production_table = table
        self.productions = production_intervals(table)

    @property
    def production_editor(self):
        """A :class:`~tonguevis.preprocess.editing.ProductionEditor` of its productions (made on
        first use, anew when the table was replaced by other means), or None without productions."""
        from tonguevis.preprocess.editing import ProductionEditor

        if self.production_table is None:
            return None
        editor = self.__dict__.get("_editor")
        if editor is None or editor.table is not self.production_table:
            editor = ProductionEditor(self.recording, self.production_table, self.path)
            self.__dict__["_editor"] = editor
        editor.path = self.path  # saved beside the recording where it is now
        return editor

    def signals(self, kind: str) -> dict[str, np.ndarray]:
        """{sensor: (N, 3)} in the unit of ``SIGNAL_KINDS[kind]`` (cached)."""
        if kind not in SIGNAL_KINDS:
            raise ValueError(f"unknown signal kind {kind!r}; choose one of {', '.join(SIGNAL_KINDS)}")
        if kind not in self._signals:
            self._signals[kind] = self._compute_signals(kind)
        return self._signals[kind]

    def _compute_signals(self, kind: str) -> dict[str, np.ndarray]:
        rec = self.recording
        names = plotted_sensors(rec)
        scale = SIGNAL_KINDS[kind][2]
        if kind == "position":
            return {n: rec.sensors[n] * scale for n in names}
        if kind == "displacement":
            return {n: (rec.sensors[n] - rest) * scale for n, rest in self._rest(names).items()}
        from tonguevis.preprocess.filtering import derivative

        order = 1 if kind == "velocity" else 2
        window = min(DERIVATIVE_WINDOW, rec.n_samples - (1 - rec.n_samples % 2))
        values = derivative(rec, order=order, window=window if window > order + 1 else None, sensors=names)
        return {n: values[n] * scale for n in names}

    def rest_sensors(self) -> list[str]:
        """The sensors a rest interval must hold valid samples of: those driving the model."""
        if self.motion is not None:
            return list(self.motion.sensor_names)
        return [n for n in TONGUE_NAMES if n in self.recording.sensors]

    def set_motion(self, motion, frames, palate=None, shown_palate=None) -> None:
        """The simulation's results: ``motion``, its drawing ``frames``, the rest it used and its note;
        the ``palate`` it was simulated against and the one the views show (see the class doc)."""
        from tonguevis.sim.motion import rest_of

        from tonguevis.io.recording import unstated_axes_note
        from tonguevis.sim.placement import size_note
        from tonguevis.sim.plausibility import plausibility_status

        self.motion, self.frames, self.rest = motion, frames, rest_of(motion)
        self.palate, self.shown_palate = palate, shown_palate
        self.notes = [plausibility_status(motion.metadata)] if "plausibility" in motion.metadata else []
        if "contact" in motion.metadata:
            self.notes.append(contact_note(motion))
        self.notes += [note] if (note := unstated_axes_note(self.recording, short=True)) else []
        self.notes += [note] if (note := size_note(motion.metadata.get("fit", {}))) else []
        self._signals.pop("displacement", None)  # displacements are from this rest now

    def _rest(self, names: list[str]) -> dict[str, np.ndarray]:
        from tonguevis.preprocess.rest import choose_rest_interval, rest_pose

        try:
            # The simulation's rest once there is one; before, the same choice it will make.
            rest = self.rest or choose_rest_interval(self.recording, given=self.given_rest)
        except TonguevisError as exc:
            # Too short for any rest window: the first valid sample is the best "rest" there is.
            logger.info("no rest interval (%s); displacements from the first valid sample", exc)
            rest = None
        out = {}
        for n in names:  # one by one: a channel lost at rest (a placeholder, a reference) spoils no other
            if rest is not None:
                try:
                    out.update(rest_pose(self.recording, rest.interval, sensors=[n]))
                    continue
                except TonguevisError:
                    pass
            valid = self.recording.valid(n)
            xyz = self.recording.sensors[n]
            out[n] = xyz[np.argmax(valid)] if valid.any() else np.zeros(3)
        return out


def contact_note(motion) -> str:
    """The palate-contact figures of a motion simulated against a palate, as one line."""
    from tonguevis.sim.plausibility import contact_line

    return contact_line({**motion.metadata, "sensor_names": list(motion.sensor_names)})


def load_session(path: str | os.PathLike, sensor_map: dict | str | None = None, rest=None, audio=None,
                 labels=None, **options) -> Session:
    """Read a recording (any supported format) and find its productions.

    rest : (start_s, end_s) to use as the rest interval (checked against the recording), or None to find it.
    audio, labels : a WAV and a Praat TextGrid to use, or None for those found beside the recording
        (see :func:`tonguevis.workflows.open_recording`).
    options : the reader's (``-O``: ``axes=``, ``channels=`` ...), as ``open_recording``.
    """
    from tonguevis.preprocess.rest import check_rest_interval
    from tonguevis.workflows.recording import open_recording

    path = Path(path)
    recording = open_recording(path, sensor_map, audio=audio, labels=labels, **options)
    if recording.n_samples < 2:
        raise RecordingError(f"the recording has {recording.n_samples} sample(s); at least 2 needed", path)
    session = make_session(recording, path)
    if rest is not None:
        session.given_rest = check_rest_interval(recording, rest, session.rest_sensors())
    release_freed_memory()  # reading and finding the productions of a long recording leave much freed
    return session


def make_session(recording: Recording, path=None) -> Session:
    """A session of ``recording`` with its productions found (when it has a tongue tip, dorsum or lips)."""
    from tonguevis.preprocess.articulators import available

    table = find_production_table(recording) if available(recording) else None
    return Session(recording, None if path is None else Path(path), production_intervals(table), table)


def remap_session(session: Session, mapping: dict[str, str]) -> Session:
    """``session`` with channels renamed by ``mapping`` (canonical name -> file channel)."""
    from tonguevis.io.sensor_map import apply_sensor_map

    recording = apply_sensor_map(session.recording, mapping, str, session.path)
    recording.metadata["sensor_map"] = dict(mapping)
    remapped = make_session(recording, session.path)
    remapped.given_rest = session.given_rest
    return remapped


def demo_recording_path() -> Path | None:
    """The demo recording (:data:`tonguevis.paths.DEMO_RECORDING`, the /ta/ train), or None if not shipped."""
    from tonguevis.paths import DEMO_RECORDING

    return DEMO_RECORDING if DEMO_RECORDING.exists() else None
