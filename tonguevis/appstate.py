"""The application state every view of the desktop app shares, without Qt.

One :class:`AppState` holds what the user is looking at: the current time,
whether playback runs and at which speed, the loop range, the selected sensor
and the colouring of the surface.  Views *subscribe* to its events and *write
back* through its setters; none of them talks to another directly (the
evented-model pattern of napari and MNE's ``ui_events``).  A plot that is
clicked calls :meth:`AppState.set_time`; every other view hears a ``"time"``
event and moves its cursor.

Nothing here imports Qt, so the state (and code steering it, such as a
script or a test) runs headless.

Events (``event.name``; ``event.value`` is the new value):

``time``       current time in seconds (float)
``playing``    playback on/off (bool)
``speed``      playback speed factor in [MIN_SPEED, MAX_SPEED] (float)
``loop``       loop range ``(start_s, end_s)`` or None
``range``      the time span ``(start_s, end_s)`` and frame period changed
``selection``  selected sensor name or None
``color``      surface colouring: one of :data:`COLOR_MODES`
``reference``  frame of reference of the 3D views: one of :data:`REFERENCE_FRAMES` ("head":
               tongue and jaw carried by the jaw's motion, palate fixed; "jaw": the jaw's
               motion removed, where the tongue is simulated)
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any, Callable

log = logging.getLogger("tonguevis")

MIN_SPEED = 0.25
MAX_SPEED = 1.0
#: Surface colourings the 3D view offers ("contact": distance to the palate).
COLOR_MODES = ("displacement", "energy", "contact", "plain")
#: Frames of reference of the 3D views (the same as tonguevis.sim.reference.REFERENCE_FRAMES).
REFERENCE_FRAMES = ("head", "jaw")
EVENT_NAMES = ("time", "playing", "speed", "loop", "range", "selection", "color", "reference")


@dataclass(frozen=True)
class Event:
    """A change of the state: ``name`` (see module doc), new ``value``, and the
    ``source`` object that caused it (a view can ignore its own echoes)."""

    name: str
    value: Any
    source: Any = None


Callback = Callable[[Event], None]


class AppState:
    """Current time, playback, loop range, selection; observers get :class:`Event`s.

    Times are seconds on the recording's clock.  ``start``/``end`` bound the
    time (the simulated motion's first and last frame); ``frame_period`` is
    the step of :meth:`step` (seconds).
    """

    def __init__(self, start: float = 0.0, end: float = 0.0, frame_period: float = 0.01):
        self._observers: dict[str, list[Callback]] = {name: [] for name in EVENT_NAMES}
        self._start = float(start)
        self._end = max(float(end), float(start))
        self._frame_period = float(frame_period)
        self._time = self._start
        self._playing = False
        self._speed = MAX_SPEED
        self._loop: tuple[float, float] | None = None
        self._selection: str | None = None
        self._color = COLOR_MODES[0]
        self._reference = REFERENCE_FRAMES[0]

    # -- observers ---------------------------------------------------------
    def subscribe(self, name: str, callback: Callback) -> Callable[[], None]:
        """Call ``callback(event)`` on every ``name`` event; returns an unsubscribe function."""
        if name not in self._observers:
            raise ValueError(f"unknown AppState event {name!r}; known: {', '.join(EVENT_NAMES)}")
        self._observers[name].append(callback)

        def unsubscribe() -> None:
            if callback in self._observers[name]:
                self._observers[name].remove(callback)

        return unsubscribe

    def _emit(self, name: str, value: Any, source: Any) -> None:
        event = Event(name, value, source)
        # Copy: an observer may unsubscribe while we iterate.
        for callback in list(self._observers[name]):
            callback(event)

    # -- time --------------------------------------------------------------
    @property
    def time(self) -> float:
        return self._time

    @property
    def start(self) -> float:
        return self._start

    @property
    def end(self) -> float:
        return self._end

    @property
    def frame_period(self) -> float:
        return self._frame_period

    def set_range(self, start: float, end: float, frame_period: float, source: Any = None) -> None:
        """New time span (a new motion was loaded); the time is clamped into it."""
        if not (math.isfinite(start) and math.isfinite(end)) or end < start:
            raise ValueError(f"time range must be finite with end >= start, got {start}..{end}")
        if not frame_period > 0:
            raise ValueError(f"frame period must be positive, got {frame_period}")
        self._start, self._end, self._frame_period = float(start), float(end), float(frame_period)
        self._loop = None
        self._emit("range", (self._start, self._end), source)
        self.set_time(self._time, source=source, force=True)

    def clamp(self, t: float) -> float:
        return min(max(float(t), self._start), self._end)

    def set_time(self, t: float, source: Any = None, force: bool = False) -> None:
        """Move every view to time ``t`` (seconds, clamped to the range)."""
        if not math.isfinite(t):
            return
        t = self.clamp(t)
        if t == self._time and not force:
            return
        self._time = t
        self._emit("time", t, source)

    def step(self, frames: int = 1, source: Any = None) -> None:
        """Move by a whole number of frames (negative = back), snapping to the frame grid."""
        index = round((self._time - self._start) / self._frame_period) + int(frames)
        self.set_time(self._start + index * self._frame_period, source=source)

    # -- playback ----------------------------------------------------------
    @property
    def playing(self) -> bool:
        return self._playing

    def set_playing(self, playing: bool, source: Any = None) -> None:
        playing = bool(playing)
        if playing == self._playing:
            return
        self._playing = playing
        self._emit("playing", playing, source)

    def toggle_playing(self, source: Any = None) -> None:
        self.set_playing(not self._playing, source)

    @property
    def speed(self) -> float:
        return self._speed

    def set_speed(self, speed: float, source: Any = None) -> None:
        """Playback speed factor, clamped to [MIN_SPEED, MAX_SPEED] (1 = real time)."""
        speed = min(max(float(speed), MIN_SPEED), MAX_SPEED)
        if speed == self._speed:
            return
        self._speed = speed
        self._emit("speed", speed, source)

    @property
    def loop(self) -> tuple[float, float] | None:
        return self._loop

    def set_loop(self, loop: tuple[float, float] | None, source: Any = None) -> None:
        """Loop playback over ``(start_s, end_s)`` (clamped to the range), or stop looping."""
        if loop is not None:
            a, b = sorted((self.clamp(loop[0]), self.clamp(loop[1])))
            loop = None if b <= a else (a, b)
        if loop == self._loop:
            return
        self._loop = loop
        self._emit("loop", loop, source)

    def playback_bounds(self) -> tuple[float, float]:
        """Where playback starts over and stops: the loop range, else the whole range."""
        return self._loop if self._loop is not None else (self._start, self._end)

    # -- selection and display ---------------------------------------------
    @property
    def selection(self) -> str | None:
        return self._selection

    def select(self, sensor: str | None, source: Any = None) -> None:
        if sensor == self._selection:
            return
        self._selection = sensor
        self._emit("selection", sensor, source)

    @property
    def color(self) -> str:
        return self._color

    def set_color(self, mode: str, source: Any = None) -> None:
        if mode not in COLOR_MODES:
            raise ValueError(f"unknown colouring {mode!r}; choose one of {', '.join(COLOR_MODES)}")
        if mode == self._color:
            return
        self._color = mode
        self._emit("color", mode, source)

    @property
    def reference(self) -> str:
        return self._reference

    def set_reference(self, frame: str, source: Any = None) -> None:
        """Show the 3D views in the head frame or the jaw frame (see :data:`REFERENCE_FRAMES`)."""
        if frame not in REFERENCE_FRAMES:
            raise ValueError(f"unknown frame of reference {frame!r}; choose one of {', '.join(REFERENCE_FRAMES)}")
        if frame == self._reference:
            return
        self._reference = frame
        self._emit("reference", frame, source)


def interval_at(intervals: list[tuple[float, float]], t: float) -> tuple[float, float] | None:
    """The ``(start, end)`` interval containing time ``t`` (the first one), or None."""
    for start, end in intervals:
        if start <= t <= end:
            return (float(start), float(end))
    return None
