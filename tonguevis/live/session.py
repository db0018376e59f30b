"""A live session without Qt: a stream's frames simulated, its rest, targets, sweeps and counters (issue 34).

:class:`LiveSession` is what the live window shows and steers, and what a script runs headless: it holds
the source, the :class:`~tonguevis.live.simulator.LiveSimulator`, the slot names, the rest (taken by
itself from the stillest half second of the first :data:`AUTO_REST_S` s, from the last half second on
request, or from the interval the settings give), the targets and the running sweep
(:class:`~tonguevis.live.session_targets.SessionTargets`), the counters, the display's low-pass and
the palate.  :meth:`LiveSession.tick` takes every frame received since the last call: each is
simulated (the dynamics need each frame at its time step) and, during a sweep, saved; the newest is
handed to the views in a :class:`LiveUpdate`, the older ones are counted as dropped from the display.

Events (``session.events``; psygnal signals of :class:`tonguevis.appstate.Event`, as the app model's):

``source``           a source was set and started (value: it) or closed (None)
``frame_processed``  a tick simulated what came (value: the newest frame's :class:`LiveUpdate`)
``rest_changed``     the rest was taken, refused or dropped (value: the line saying so;
                     ``session.simulator`` is the simulation on it, or None)
``targets_changed``  a target was added or removed (value: the list of targets)
``sweep_changed``    a sweep started or stopped (value: the line saying so; ``session.sweep`` the running one)
``status``           a line for the status bar (str)
``error``            what the clinician must see (str): a source that cannot start, a sweep not saved
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass

import numpy as np
from psygnal import Signal, SignalGroup

from tonguevis._logging import logger
from tonguevis.appstate import Event, emit_event
from tonguevis.errors import TonguevisError
from tonguevis.live.display_filter import DisplayLowPass
from tonguevis.live.palatogram import LivePalatogram
from tonguevis.live.rest import simulator_on_rest
from tonguevis.live.session_targets import SessionTargets
from tonguevis.live.velum import LiveVelum
from tonguevis.live.simulator import REST_SEARCH_S, LiveSimulationError, LiveSimulator, check_live_settings

#: The rest is taken by itself from the stillest half second of the first seconds of the stream.
AUTO_REST_S = REST_SEARCH_S
#: Frames simulated in one tick at most: after a stall the older ones of a burst are skipped (and counted).
MAX_BURST = 50
#: Frames over which the session judges whether the model follows the sensors (one second at 100 Hz) ...
FOLLOW_WINDOW = 100
#: ... and the share of them the model could not follow (the integrator's linear fallback, LiveStep.recovered)
#: above which it says so: the replay refuses a recording with more than this share of such frames
#: (:data:`tonguevis.sim.motion_builder.RECOVERED_SHARE`).  On the shared /ta/ 009 streamed, the rest taken by
#: itself (0.06-0.56 s, the jaw opening before speech) left 591 of the 793 frames after it unfollowed from 5 s
#: on, drawn without a word: the tongue a clinician saw was not the speaker's.
NOT_FOLLOWING_SHARE = 0.10


class LiveEvents(SignalGroup):
    """A live session's events: one signal of :class:`~tonguevis.appstate.Event` per name of the module's table."""

    source = Signal(Event)
    frame_processed = Signal(Event)
    rest_changed = Signal(Event)
    targets_changed = Signal(Event)
    sweep_changed = Signal(Event)
    status = Signal(Event)
    error = Signal(Event)


@dataclass
class LiveUpdate:
    """The newest frame of a tick, simulated, as the views draw it (metres, the speaker frame).

    frame : the :class:`~tonguevis.live.source.LiveFrame`.  names : the stream's S slot names.
    step : the simulator's :class:`~tonguevis.live.simulator.LiveStep` (None before a rest, or once the
        simulation stopped).  time_s : the frame's time on the session's clock (s from the first frame,
        or from the sweep's start).
    sensors_head : (S, 3) every slot head-corrected (the stream's positions without a simulation).
    surface : (k, 3) the tongue's surface nodes as drawn (the jaw's offset added, low-passed); None without a step.
    sensors : (S', 3) the sensors as drawn (low-passed): the driving ones on the model with a simulation,
        else every slot.
    targets : [(centre (3,), NaN where it cannot be placed; accuracy %, NaN when unknown)], one per target.
    ghost : the first replay target's template sensors now ({name: (3,)}), or None.
    frames : frames this tick took from the source (1: no backlog); simulate_s : seconds simulating them;
    started_s : :func:`time.perf_counter` when the tick began.
    velum_lift : m, the speaker's velum lifted by the dorsum at this frame (:mod:`tonguevis.live.velum`; 0: at rest
        or no such palate).
    """

    frame: object
    names: list
    step: object
    time_s: float
    sensors_head: np.ndarray
    surface: np.ndarray | None
    sensors: np.ndarray
    targets: list
    ghost: dict | None
    frames: int
    simulate_s: float
    started_s: float
    velum_lift: float = 0.0


class LiveSession(SessionTargets):
    """A live stream simulated, with its rest, targets and sweeps (see the module docstring).

    settings : a :class:`~tonguevis.sim.settings.RunSettings` (default everyone's: the replay's); its
        ``palate`` is placed on the rest, its ``rest`` (START, END s on the stream's clock from the first
        frame) taken when the stream passes END instead of the stillest moment.  model : the unplaced
        tongue model (built on the first rest and kept when None).  sensor_names : the slots' names, a list
        in slot order or a sensor map (name -> NDI Id); without it the device's (:meth:`slot_names`).
    profile : a :class:`~tonguevis.live.profiles.Profile` (targets, offsets; sweeps saved in its folder under
        ``profiles_root``); None: the profile "default" there.  auto_rest : take the rest by itself.
    """

    def __init__(self, settings=None, *, model=None, sensor_names=None, profile=None, profiles_root=None,
                 auto_rest: bool = True):
        from tonguevis.sim.settings import RunSettings

        settings = settings if settings is not None else RunSettings()
        check_live_settings(settings)
        self.events = LiveEvents()
        self.settings, self.model = settings, model
        self.given_names = (dict(sensor_names) if isinstance(sensor_names, dict) else list(sensor_names)) \
            if sensor_names else None
        self.profiles_root = profiles_root
        self.profile = profile if profile is not None else self._default_profile()
        self.targets = list(self.profile.targets)
        self.auto_rest = auto_rest
        self.palate = settings.palate_surface()  # unplaced: the simulator places it on the rest
        self.source = None
        self.simulator: LiveSimulator | None = None
        self.rest_line = self._rest_plain = "waiting for a still moment"
        self._followed: deque = deque(maxlen=FOLLOW_WINDOW)  # the last frames' LiveStep.recovered
        self.not_following_since: float | None = None  # the session's clock (s) when it stopped following
        self.sweep = None
        self.last_saved = None
        self.low_pass = DisplayLowPass()  # of what is drawn (off by default)
        self._recent: deque = deque(maxlen=int(REST_SEARCH_S * 200))
        self.epg = None  # the LivePalatogram of the rest's palate
        self.velum = None  # the LiveVelum of the rest's palate, when its velum lifts
        self.latest: LiveUpdate | None = None
        self.reset_counters()

    def reset_counters(self) -> None:
        """Count from now: frames received, dropped from the display (a newer one came in the same tick) and
        skipped (not even simulated: a burst beyond MAX_BURST); the clock starts again at the next frame."""
        self.frames_received = 0
        self.dropped_frames = 0
        self.skipped_frames = 0
        self.accuracy: dict[int, float] = {}
        self.last_frame = None
        self._clock0 = None

    def _emit(self, name: str, value) -> None:
        emit_event(self.events, name, value, self)

    def say(self, text: str) -> None:
        """A line for the status bar."""
        self._emit("status", text)

    # ------------------------------------------------------------------ the source
    def set_source(self, source) -> bool:
        """Use ``source`` (started here if it is not): :meth:`tick` takes its frames from now on.
        A source that cannot start is an ``error`` event, not raised (returns False)."""
        self.close_source()
        self.source = source
        try:
            source.start()
        except Exception as exc:  # noqa: BLE001 (any source's failure is said, never a crash)
            self._emit("error", f"cannot start the live source: {exc}")
            return False
        self.reset_counters()
        self._emit("source", source)
        return True

    def close_source(self) -> None:
        if self.source is not None:
            try:
                self.source.close()
            except Exception:  # closing must never fail the window
                logger.exception("closing the live source failed")
            self.source = None
            self._emit("source", None)

    # ------------------------------------------------------------------ the frame loop
    def _pending(self) -> list:
        """Every frame received since the last tick (oldest first); the newest alone without a queue."""
        source = self.source
        frames = []
        if getattr(source, "queued", False):
            while (frame := source.get(0)) is not None:
                frames.append(frame)
        else:
            frame = source.latest()
            if frame is not None and (self.last_frame is None or frame.frame != self.last_frame.frame):
                frames.append(frame)
        return frames

    def tick(self) -> LiveUpdate | None:
        """Simulate every frame received since the last call (see :meth:`process`); None when none came."""
        if self.source is None:
            return None
        frames = self._pending()
        return self.process(frames) if frames else None

    def process(self, frames: list) -> LiveUpdate:
        """Simulate ``frames`` (LiveFrames, oldest first; at most MAX_BURST, the older ones skipped), add them to
        the sweep, take the rest when it is time: a ``frame_processed`` event with the newest one's update."""
        started = time.perf_counter()
        self.frames_received += len(frames)
        if len(frames) > MAX_BURST:
            self.skipped_frames += len(frames) - MAX_BURST
            frames = frames[-MAX_BURST:]
        newest = frames[-1]
        names = self.slot_names(newest.n_sensors)
        for frame in frames:
            self._recent.append((frame.timestamp_s, np.asarray(frame.positions, dtype=np.float64)))
        if self._clock0 is None:
            self._clock0 = frames[0].timestamp_s  # the first frame kept (a burst holds several)
        if self.simulator is None and self.auto_rest and len(self._recent) >= 2:
            given = self.settings.rest
            if given is not None:  # the rest the user gave: when the stream has passed its end
                if newest.timestamp_s - self._clock0 >= given[1]:
                    self.take_rest(names, interval=given)
            elif self._recent[-1][0] - self._recent[0][0] >= AUTO_REST_S - 1e-9:
                self.take_rest(names, stillest=True)
        if self.simulator is not None and self.simulator.sensor_names != names:
            self.simulator = None  # the slots changed (another device): a new rest is needed
            self._rest_said("the stream's sensors changed: take the rest again")
        step, simulate_s = None, 0.0
        for k, frame in enumerate(frames):
            corrected = None
            if self.simulator is not None:
                try:
                    step = self.simulator.step(frame.positions, reconstruct=k == len(frames) - 1)
                except (LiveSimulationError, ValueError, np.linalg.LinAlgError) as exc:
                    self.say(f"simulation stopped: {exc}")
                    self.simulator, step = None, None
                else:
                    simulate_s += sum(v for key, v in step.timings.items() if key != "reconstruct")
                    corrected = step.corrected
                    self._followed.append(step.recovered)
            if self.sweep is not None:
                self._add_to_sweep(frame, corrected)
        if step is not None:
            self._check_following(newest)
        self.dropped_frames += len(frames) - 1
        update = self._update(newest, names, step, started, len(frames), simulate_s)
        self.last_frame, self.latest = newest, update
        self._emit("frame_processed", update)
        return update

    def _update(self, frame, names, step, started: float, n_frames: int, simulate_s: float) -> LiveUpdate:
        dt = 0.0 if self.last_frame is None else frame.timestamp_s - self.last_frame.timestamp_s
        sim = self.simulator
        if step is not None and sim is not None:
            surface = self.low_pass("surface", step.surface + step.jaw_offset, dt)
            sensors_head = step.corrected
            sensors = self.low_pass("sensors", sim.sensor_points_in_view(step), dt)
        else:
            surface, sensors_head = None, np.asarray(frame.positions, dtype=np.float64) / 1000.0
            sensors = self.low_pass("sensors", sensors_head, dt)
        targets, ghost = self.place_targets(frame, names, sensors_head)
        lift = 0.0
        if step is not None and self.velum is not None:  # on the sensors as measured, not the display's smoothing
            lift = self.velum.lift(sim.sensor_points_in_view(step))
        return LiveUpdate(frame, names, step, self.clock(frame), sensors_head, surface, sensors, targets, ghost,
                          n_frames, simulate_s, started, lift)

    # ------------------------------------------------------------------ display smoothing
    @property
    def smoothing(self) -> float:
        """The time constant (s) of the display's low-pass (0: off)."""
        return self.low_pass.time_constant

    def set_smoothing(self, seconds: float) -> None:
        """Low-pass what is drawn with this time constant (s; 0: off).  What is saved stays raw."""
        self.low_pass.set_time_constant(seconds)

    # ------------------------------------------------------------------ the rest
    def _rest_said(self, line: str, advice: str = "") -> None:
        """The rest's line (``rest_line``, ``rest_changed``): ``line``, and after it ``advice`` while it holds."""
        self._rest_plain = line
        self.rest_line = f"{line}; {advice}" if advice else line
        self._emit("rest_changed", self.rest_line)

    def _check_following(self, newest) -> None:
        """Say when the model stops following the sensors (more than :data:`NOT_FOLLOWING_SHARE` of the last
        :data:`FOLLOW_WINDOW` frames unfollowed), on the rest's line and the status bar, and when it follows
        again (a whole window followed)."""
        if len(self._followed) < FOLLOW_WINDOW // 2:
            return
        share = float(np.mean(self._followed))
        if self.not_following_since is None and share > NOT_FOLLOWING_SHARE:
            self.not_following_since = self.clock(newest)
            advice = (f"the model is not following the sensors since {self.not_following_since:.1f} s "
                      f"({100 * share:.0f} % of the last frames could not be simulated): take the rest again at a "
                      "still moment")
            self._rest_said(self._rest_plain, advice)
            self.say(advice)
        elif self.not_following_since is not None and share == 0.0 and len(self._followed) == FOLLOW_WINDOW:
            self.not_following_since = None
            self._rest_said(self._rest_plain)
            self.say("the model follows the sensors again")

    def take_rest(self, names: list[str] | None = None, *, stillest: bool = False, interval=None) -> bool:
        """The rest from the stillest moment of the recent frames, ``interval`` (start_s, end_s on the session's
        clock from its first frame), else the last half second.  names : the slots' (default
        :meth:`slot_names`).  A rest that cannot be taken is said (``rest_changed``, ``status``), never raised."""
        if len(self._recent) < 2 or self.last_frame is None and names is None:
            self.say("no frames yet to take the rest from")
            return False
        names = names if names is not None else self.slot_names(self.last_frame.n_sensors)
        try:
            sim = simulator_on_rest(list(self._recent), names, self.settings, self.model, stillest=stillest,
                                    interval=interval, clock0=self._clock0 or 0.0)
        except (TonguevisError, ValueError) as exc:
            self.auto_rest = False  # said once; the clinician presses the button when the patient is still
            self._rest_said(f"no rest: {exc}")
            self.say(f"cannot take the rest: {exc}")
            return False
        if self.model is None:
            self.model = sim.source_model  # built once, kept for the next rest
        self.simulator = sim
        self.low_pass.reset()
        self._followed.clear()
        self.not_following_since = None
        self._palatogram_layout(sim)
        # On the session's clock (0 at its first frame, as a given rest is), not the device's or a looping
        # replay server's, whose time stamps run on from wherever it was (40 s into a 17 s recording's third lap).
        origin = self._clock0 if self._clock0 is not None else sim.rest_times[0]
        start, end = sim.rest_times[0] - origin, sim.rest_times[-1] - origin
        how = "(stillest moment)" if stillest else "(as given)" if interval is not None else "taken"
        self._rest_said(f"rest {how}: {start:.2f}-{end:.2f} s after the first frame; {len(sim.driving_names)} "
                        f"sensors drive the tongue ({', '.join(sim.driving_names)}), {self.settings.modes} modes")
        self.say("rest taken")
        return True

    def take_rest_now(self) -> bool:
        """The rest from the last half second (the patient holds still when the button is pressed)."""
        if self.last_frame is None:
            self.say("no frames yet to take the rest from")
            return False
        return self.take_rest(self.slot_names(self.last_frame.n_sensors))

    # ------------------------------------------------------------------ the palatogram
    def _palatogram_layout(self, sim) -> None:
        self.epg = None
        self.velum = LiveVelum(sim.palate) if LiveVelum.liftable(sim.palate) else None
        if sim.palate is not None:
            try:
                self.epg = LivePalatogram(sim)
            except Exception as exc:  # noqa: BLE001 (the palatogram is an extra: the session goes on without it)
                logger.info("no live palatogram: %s", exc)

    def palatogram(self, update: LiveUpdate) -> np.ndarray | None:
        """The electrode contacts of ``update``'s simulated surface when one is due (see
        :class:`~tonguevis.live.palatogram.LivePalatogram`), else None."""
        if update.step is None or self.epg is None:
            return None
        return self.epg.contacts(update.step, update.frame.timestamp_s, update.velum_lift)
