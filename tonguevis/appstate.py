"""The application model every view of the desktop app shares, without Qt.

One :class:`AppState` holds what the app has open and what the user is looking
at: the open recordings (*sessions*: a primary one and room for a second one to
compare with), the motions the analyses can use, the morph's two ends, the tongue
model the simulations share, the status line, and the view state (the current
time, playback and its speed, the loop range, the selected sensor, the colouring
and the frame of reference).  Views *subscribe* to its events and *write back*
through its setters; none of them talks to another or to the window directly (the
evented-model pattern of napari and MNE's ``ui_events``).  A plot that is clicked
calls :meth:`AppState.set_time`; every other view hears a ``"time"`` event and
moves its cursor.  The Energy tab's "Morph source" button calls
:meth:`AppState.set_morph_end`; the Morph tab hears ``"morph_ends"``.

Nothing here imports Qt, so the state (and code steering it, such as a
script or a test) runs headless.  Every setter is called on the GUI thread: a
worker hands its results back and the GUI thread writes them here.

Events (``event.name``; ``event.value`` is the new value; ``event.key`` says which
of several slots changed, where there are several):

``time``          current time in seconds (float)
``playing``       playback on/off (bool)
``speed``         playback speed factor in [MIN_SPEED, MAX_SPEED] (float)
``loop``          loop range ``(start_s, end_s)`` or None
``range``         the time span ``(start_s, end_s)`` and frame period changed
``selection``     selected sensor name or None
``color``         surface colouring: one of :data:`COLOR_MODES`
``reference``     frame of reference of the 3D views: one of :data:`REFERENCE_FRAMES` ("head":
                  tongue and jaw carried by the jaw's motion, palate fixed; "jaw": the jaw's
                  motion removed, where the tongue is simulated)
``session``       a recording was opened (or closed: None) in slot ``key``, one of
                  :data:`SESSION_ROLES` ("primary": the one the views show; "compare": a second one)
``motion``        the session in slot ``key`` has its simulated motion now (value: the session)
``productions``   the productions of the session in slot ``key`` were corrected (value: the session)
``motions``       the motions the analyses can use changed (value: {name: Motion})
``morph_ends``    the morph's ``key`` end (one of :data:`MORPH_ENDS`) is ``(recording name, time_s)``
``tongue_model``  the tongue model every simulation uses (value: the model or None: built on need)
``run_settings``  how the app simulates (value: a :class:`tonguevis.sim.settings.RunSettings`)
``status``        a line for the status bar (str); sent every time, even when the text repeats
``frame_drawn``   a 3D view drew the motion's frame ``value`` (int; ``source`` is the view): what
                  another view draws in step with it (the compare panel's B, its difference colours)
``live_session``  the live session the live views show (a :class:`tonguevis.live.session.LiveSession`,
                  or None: closed); its frames, rest, targets and sweeps have events of their own

The events are typed signals (psygnal, as napari's evented models): ``state.events.time``
is a signal of :class:`Event`; ``state.events.time.connect(callback)`` subscribes and
``.disconnect(callback)`` stops.  A misspelt event name is an AttributeError at once,
where a string name failed only when the event was first sent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

from psygnal import EmitLoopError, Signal, SignalGroup

from tonguevis.render.production_marks import interval_at  # noqa: F401 (the views' import of it)


MIN_SPEED = 0.25
MAX_SPEED = 1.0
#: Surface colourings the 3D view offers ("contact": distance to the palate; "difference": distance
#: to the compared recording's tongue, while one is compared).
COLOR_MODES = ("displacement", "energy", "contact", "plain", "difference")
#: Frames of reference of the 3D views (the same as tonguevis.sim.reference.REFERENCE_FRAMES).
REFERENCE_FRAMES = ("head", "jaw")
#: Slots of the open recordings: the primary one the views show, a second one to compare with.
SESSION_ROLES = ("primary", "compare")
#: The morph's ends: t = 0 and t = 1.
MORPH_ENDS = ("source", "target")
#: How a compared recording (B) is shown: beside A (its own view) or as a translucent ghost in A's views.
COMPARE_LAYOUTS = ("side", "ghost")
#: How B's time follows A's (:class:`tonguevis.analysis.compare.Comparison`'s modes).
COMPARE_TIME_MODES = ("production", "absolute")
EVENT_NAMES = ("time", "playing", "speed", "loop", "range", "selection", "color", "reference",
               "session", "motion", "productions", "motions", "morph_ends", "tongue_model", "run_settings", "status",
               "frame_drawn", "compare_view", "comparison", "live_session")


@dataclass(frozen=True)
class CompareView:
    """How the compared recording is shown: ``layout`` (:data:`COMPARE_LAYOUTS`) and ``time_mode``
    (:data:`COMPARE_TIME_MODES`)."""

    layout: str = "side"
    time_mode: str = "production"


@dataclass(frozen=True)
class Event:
    """A change of the state: ``name`` (see module doc), new ``value``, the
    ``source`` object that caused it (a view can ignore its own echoes), and the
    ``key`` of the slot that changed (a session role, a morph end; else None)."""

    name: str
    value: Any
    source: Any = None
    key: str | None = None


Callback = Callable[[Event], None]


class AppEvents(SignalGroup):
    """The app model's events: one signal of :class:`Event` per name of the module's table."""

    time = Signal(Event)
    compare_view = Signal(Event)
    comparison = Signal(Event)
    playing = Signal(Event)
    speed = Signal(Event)
    loop = Signal(Event)
    range = Signal(Event)
    selection = Signal(Event)
    color = Signal(Event)
    reference = Signal(Event)
    session = Signal(Event)
    motion = Signal(Event)
    productions = Signal(Event)
    motions = Signal(Event)
    morph_ends = Signal(Event)
    tongue_model = Signal(Event)
    run_settings = Signal(Event)
    status = Signal(Event)
    frame_drawn = Signal(Event)
    live_session = Signal(Event)


def emit_event(events: SignalGroup, name: str, value: Any, source: Any = None, key: str | None = None) -> None:
    """Send an :class:`Event` on ``events``' signal ``name``; a subscriber's error is raised as it raised it
    (psygnal wraps it in an EmitLoopError)."""
    try:
        getattr(events, name).emit(Event(name, value, source, key))
    except EmitLoopError as exc:
        raise (exc.__cause__ or exc) from None


def connected(signal, callback: Callback) -> Callable[[], None]:
    """Connect ``callback`` to ``signal`` (e.g. ``state.events.time``); returns the function that
    disconnects it (views that close keep it).

    The signal holds ``callback`` strongly: psygnal would hold a bound method weakly, and a Qt
    view's Python wrapper may be collected while its widget lives on, silently deafening it.
    """
    def relay(event: Event) -> None:
        callback(event)

    signal.connect(relay)

    def disconnect() -> None:
        signal.disconnect(relay, missing_ok=True)

    return disconnect


class AppState:
    """Open sessions, motions, morph ends, status; current time, playback, loop range,
    selection; observers get :class:`Event`s.

    Times are seconds on the recording's clock.  ``start``/``end`` bound the
    time (the simulated motion's first and last frame); ``frame_period`` is
    the step of :meth:`step` (seconds).
    """

    def __init__(self, start: float = 0.0, end: float = 0.0, frame_period: float = 0.01):
        self.events = AppEvents()
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
        self._sessions: dict[str, Any] = {}
        self._motions: dict[str, Any] = {}
        self._morph_ends: dict[str, tuple[str, float] | None] = {end: None for end in MORPH_ENDS}
        self._tongue_model: Any = None
        from tonguevis.sim.settings import RunSettings

        self._run_settings = RunSettings()
        self._status = ""
        self._compare_view = CompareView()
        self._comparison: Any = None
        self._live_session: Any = None

    # -- events ----------------------------------------------------------
    def _emit(self, name: str, value: Any, source: Any, key: str | None = None) -> None:
        emit_event(self.events, name, value, source, key)

    def frame_drawn(self, index: int, source: Any) -> None:
        """``source`` (a 3D view) drew frame ``index``: a ``frame_drawn`` event."""
        self._emit("frame_drawn", int(index), source)

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


    # -- the comparison of two recordings --------------------------------------
    @property
    def compare_view(self) -> CompareView:
        return self._compare_view

    def set_compare_view(self, source: Any = None, **changes: str) -> None:
        """Show the compared recording another way: ``layout=``, ``time_mode=`` (see :class:`CompareView`)."""
        from dataclasses import replace

        view = replace(self._compare_view, **changes)
        if view.layout not in COMPARE_LAYOUTS:
            raise ValueError(f"compare layout must be one of {', '.join(COMPARE_LAYOUTS)}, got {view.layout!r}")
        if view.time_mode not in COMPARE_TIME_MODES:
            raise ValueError(f"compare time must be one of {', '.join(COMPARE_TIME_MODES)}, got {view.time_mode!r}")
        if view == self._compare_view:
            return
        self._compare_view = view
        self._emit("compare_view", view, source)

    @property
    def comparison(self) -> Any:
        """What the views show of the comparison of the two sessions (the compare panel's
        :class:`~tonguevis.gui.compare.ShownComparison`), None when none is shown."""
        return self._comparison

    def set_comparison(self, shown: Any, source: Any = None) -> None:
        self._comparison = shown
        self._emit("comparison", shown, source)

    # -- sessions: the open recordings ---------------------------------------
    @staticmethod
    def _check_role(role: str) -> None:
        if role not in SESSION_ROLES:
            raise ValueError(f"unknown session role {role!r}; choose one of {', '.join(SESSION_ROLES)}")

    @property
    def sessions(self) -> dict[str, Any]:
        """{role: session} of the open recordings (a copy; roles without one left out)."""
        return dict(self._sessions)

    @property
    def session(self) -> Any:
        """The primary session (the recording the views show), or None."""
        return self._sessions.get("primary")

    def session_of(self, role: str) -> Any:
        self._check_role(role)
        return self._sessions.get(role)

    def role_of(self, session: Any) -> str | None:
        """The role ``session`` (the object itself) is open in, or None."""
        return next((role for role, open_ in self._sessions.items() if open_ is session), None)

    def set_session(self, session: Any, role: str = "primary", source: Any = None) -> None:
        """Open ``session`` in ``role`` (None closes the role): a ``session`` event keyed by the role.

        Setting the same object again sends the event again (the views start over with it)."""
        self._check_role(role)
        if session is None:
            if self._sessions.pop(role, None) is None:
                return
        else:
            self._sessions[role] = session
        self._emit("session", session, source, role)

    def set_motion(self, session: Any, source: Any = None) -> str | None:
        """``session`` has its simulated motion now (set on it by the GUI thread): a ``motion`` event
        keyed by its role.  A session no longer open (a newer one replaced it) is ignored: returns
        its role, or None when it was not open."""
        role = self.role_of(session)
        if role is not None:
            self._emit("motion", session, source, role)
        return role

    def set_productions(self, session: Any, table: Any, source: Any = None) -> str | None:
        """``session``'s productions are now ``table`` (a ProductionTable, e.g. corrected by hand):
        set on the session (``session.set_production_table``), then a ``productions`` event keyed
        by its role.  A session no longer open is ignored: returns its role, or None."""
        role = self.role_of(session)
        if role is not None:
            session.set_production_table(table)
            self._emit("productions", session, source, role)
        return role

    def follow_session(self, callback: Callable[[Any], None], role: str = "primary") -> Callable[[], None]:
        """Call ``callback(session)`` when a session opens in ``role`` and when its motion is ready
        (every view showing a session needs both); returns an unsubscribe function."""
        self._check_role(role)

        def relay(event: Event) -> None:
            if event.key == role:
                callback(event.value)

        stops = [connected(self.events.session, relay), connected(self.events.motion, relay)]

        def unsubscribe() -> None:
            for stop in stops:
                stop()

        return unsubscribe

    # -- motions the analyses can use ------------------------------------------
    @property
    def motions(self) -> dict[str, Any]:
        """{recording name: Motion} of every motion simulated in this run of the app (a copy)."""
        return dict(self._motions)

    def add_motions(self, motions: dict[str, Any], source: Any = None) -> None:
        """Add (or replace by name) motions; one ``motions`` event with all of them."""
        if not motions:
            return
        self._motions.update(motions)
        self._emit("motions", dict(self._motions), source)

    # -- the morph's ends ------------------------------------------------------
    @property
    def morph_ends(self) -> dict[str, tuple[str, float] | None]:
        """{"source": (recording, time_s) or None, "target": ...}."""
        return dict(self._morph_ends)

    def set_morph_end(self, end: str, recording: str, time: float, source: Any = None) -> None:
        """Make frame ``time`` (s) of ``recording`` the morph's ``end`` ("source": t = 0, "target": t = 1)."""
        if end not in MORPH_ENDS:
            raise ValueError(f"unknown morph end {end!r}; choose one of {', '.join(MORPH_ENDS)}")
        if not math.isfinite(time):
            raise ValueError(f"the morph's {end} time must be finite, got {time}")
        value = (str(recording), float(time))
        self._morph_ends[end] = value
        self._emit("morph_ends", value, source, end)

    # -- the tongue model every simulation shares --------------------------------
    @property
    def tongue_model(self) -> Any:
        """The TongueModel the simulations use, or None until one is built (then handed back here)."""
        return self._tongue_model

    @property
    def mesh_path(self) -> Any:
        """The mesh the model is built on (None: the shipped tongue): the run settings' ``mesh``."""
        return self._run_settings.mesh

    def set_tongue_model(self, model: Any, mesh_path: Any = None, source: Any = None) -> None:
        """Use ``model`` (built on ``mesh_path``; None: the shipped mesh) for every simulation from now on."""
        if mesh_path != self._run_settings.mesh:  # first: a new mesh drops the old model
            self.set_run_settings(self._run_settings.replace(mesh=mesh_path), source)
        self._tongue_model = model
        self._emit("tongue_model", model, source)

    # -- how the app simulates ----------------------------------------------------------
    @property
    def run_settings(self):
        """The :class:`~tonguevis.sim.settings.RunSettings` every simulation of the app uses."""
        return self._run_settings

    def set_run_settings(self, settings, source: Any = None) -> None:
        """Simulate with ``settings`` from now on (a new mesh drops the model built on the old one)."""
        old, self._run_settings = self._run_settings, settings
        if settings.model_fields() != old.model_fields() and self._tongue_model is not None:
            self._tongue_model = None
            self._emit("tongue_model", None, source)
        self._emit("run_settings", settings, source)

    def change_run_settings(self, source: Any = None, **changes: Any) -> None:
        """Change some fields of the run settings (``modes=``, ``palate=``...)."""
        self.set_run_settings(self._run_settings.replace(**changes), source)

    # -- status ------------------------------------------------------------------
    @property
    def status(self) -> str:
        return self._status

    def set_status(self, text: str, source: Any = None) -> None:
        """A line for the status bar (sent even when it repeats: the bar may show something else now)."""
        self._status = str(text)
        self._emit("status", self._status, source)

    # -- the live session ---------------------------------------------------------
    @property
    def live_session(self) -> Any:
        """The live session (a :class:`tonguevis.live.session.LiveSession`) the live views show, or None."""
        return self._live_session

    def set_live_session(self, session: Any, source: Any = None) -> None:
        """Show ``session`` in the live views from now on (None: none); the one it replaces is not closed here
        (its window closes its source)."""
        if session is self._live_session:
            return
        self._live_session = session
        self._emit("live_session", session, source)
