"""A live session's profile side: who the slots are, and the targets and sweeps placed on the stream,
scored, recorded (the part of :class:`tonguevis.live.session.LiveSession` that is the biofeedback exercise).

Targets are placed where the tongue tip is now (a static one, one oscillating 10 mm below it, one
following the jaw), or given whole (a :class:`~tonguevis.live.targets.ReplayTarget` and its ghost);
each frame places them on the session's clock and scores the tip against them (during a sweep,
the sweep scores every frame).  They are fixed while a sweep records.  Metres, seconds.
"""

from __future__ import annotations

import numpy as np

from tonguevis.errors import TonguevisError
from tonguevis.live.targets import FollowingTarget, OscillatingTarget, ReplayTarget, StaticTarget, TargetError


class SessionTargets:
    """The profile's side of a :class:`~tonguevis.live.session.LiveSession` (its base): the slots' names,
    the sensors' offsets, the targets and the sweeps (using the session's ``last_frame``, ``simulator``,
    ``source``, events)."""

    # ------------------------------------------------------------------ the profile: who the slots are
    def _default_profile(self):
        from tonguevis.live.profiles import Profile, ProfileError, load_profile

        try:
            return load_profile("default", self.profiles_root)
        except ProfileError:
            return Profile("default", name="default")

    def slot_names(self, n_slots: int) -> list[str]:
        """The stream's slot names: a sensor map given (name -> NDI Id, matched to the ids the device listed,
        else to the slot numbers) or a list given, else the names the device sent, else the profile's map
        (name -> slot), else slot0, slot1, ..."""
        given = self.given_names
        if isinstance(given, dict) and given:
            ids = getattr(self.source, "sensor_ids", None)
            ids = list(ids) if ids and len(ids) == n_slots else list(range(n_slots))
            by_id = {int(i): str(name) for name, i in given.items()}
            return [by_id.get(int(i), f"slot{k}") for k, i in enumerate(ids)]
        if given and len(given) >= n_slots:
            return [str(n) for n in given[:n_slots]]
        names = getattr(self.source, "sensor_names", None)
        if names and len(names) == n_slots:
            return list(names)
        if self.profile.sensor_map:
            by_slot = {slot: name for name, slot in self.profile.sensor_map.items()}
            return [by_slot.get(k, f"slot{k}") for k in range(n_slots)]
        return [f"slot{k}" for k in range(n_slots)]

    # ------------------------------------------------------------------ where the targets go
    def sensor_dict(self, names: list[str], positions: np.ndarray) -> dict[str, np.ndarray]:
        """{slot name: (3,) m} of (S, 3) ``positions``, each with the profile's offset for that sensor."""
        from tonguevis.live.profiles import apply_sensor_offsets

        return apply_sensor_offsets({n: positions[k] for k, n in enumerate(names)}, self.profile.sensor_offsets)

    def clock(self, frame) -> float:
        """``frame``'s time (s) from the sweep's start during a sweep, else from the session's first frame."""
        if self.sweep is not None and self.sweep.start_s is not None:
            return frame.timestamp_s - self.sweep.start_s
        return frame.timestamp_s - (self._clock0 or 0.0)

    def _tip(self) -> tuple[str, np.ndarray] | None:
        """(scored sensor, its head-frame position m now) for new targets; None (said) when unknown."""
        frame = self.last_frame
        if frame is None:
            self.say("no frame yet: targets are placed at the tongue tip's current position")
            return None
        names = self.slot_names(frame.n_sensors)
        sensor = "TT" if "TT" in names else next((n for n in names if n.startswith("T")), names[0])
        if self.simulator is not None and self.simulator.ready:
            position = self.simulator.last_corrected[names.index(sensor)]
        else:
            position = np.asarray(frame.positions[names.index(sensor)], dtype=float) / 1000.0
        position = self.sensor_dict([sensor], position[None])[sensor]
        if not np.all(np.isfinite(position)):
            self.say(f"{sensor} is missing now: no target placed")
            return None
        return sensor, position

    def place_targets(self, frame, names: list[str], sensors_head: np.ndarray) -> tuple[list, dict | None]:
        """[(centre (3,) m, accuracy %)] of every target at ``frame`` (scored here unless a sweep scores them)
        and the first replay target's ghost ({sensor: (3,) m}, or None)."""
        sensors = self.sensor_dict(names, sensors_head)
        t = self.clock(frame)
        placed, ghost = [], None
        for j, target in enumerate(self.targets):
            try:
                centre = target.position_at(t, sensors)
                if self.sweep is None:
                    self.accuracy[j] = float(target.score(t, sensors)[1])
            except TargetError as exc:
                self.say(str(exc))
                centre = np.full(3, np.nan)
            placed.append((centre, self.accuracy.get(j, np.nan)))
            if isinstance(target, ReplayTarget) and target.template and ghost is None:
                ghost = target.ghost_at(t)
        return placed, ghost

    # ------------------------------------------------------------------ adding and removing
    def add_target(self, target) -> None:
        """Add any :class:`~tonguevis.live.targets.Target` (e.g. a ReplayTarget with its ghost)."""
        if self.sweep is not None:
            self.say("targets are fixed during a sweep: stop it first")
            return
        self.targets.append(target)
        self._targets_changed()

    def add_static_target(self, radius: float) -> None:
        """A static target of ``radius`` m at the tongue tip's position now."""
        tip = self._tip()
        if tip is not None:
            sensor, p = tip
            self.add_target(StaticTarget(p, radius, sensor=sensor, name=f"static {len(self.targets) + 1}"))

    def add_oscillating_target(self, radius: float, frequency: float) -> None:
        """A target oscillating at ``frequency`` Hz between the tip's position now and 10 mm below it."""
        tip = self._tip()
        if tip is not None:
            sensor, p = tip
            self.add_target(OscillatingTarget(p, p - np.array([0.0, 0.0, 0.01]), frequency, radius, sensor=sensor,
                                              name=f"oscillating {len(self.targets) + 1}"))

    def add_following_target(self, radius: float) -> None:
        """A target following the jaw (else a head reference) where the tip is now relative to it."""
        tip = self._tip()
        if tip is None:
            return
        sensor, p = tip
        names = self.slot_names(self.last_frame.n_sensors)
        follows = "JAW" if "JAW" in names else next((n for n in names if n != sensor), None)
        if follows is None:
            self.say("a following target needs another sensor to follow")
            return
        positions = self.simulator.last_corrected if self.simulator is not None else \
            np.asarray(self.last_frame.positions, dtype=float) / 1000.0
        anchor = self.sensor_dict(names, positions)[follows]
        if not np.all(np.isfinite(anchor)):
            self.say(f"{follows} is missing now: no target placed")
            return
        self.add_target(FollowingTarget(follows, p - anchor, radius, sensor=sensor,
                                        name=f"following {follows} {len(self.targets) + 1}"))

    def remove_target(self, index: int = -1) -> None:
        """Remove target ``index`` (the last one when it is out of range)."""
        if self.sweep is not None:
            self.say("targets are fixed during a sweep: stop it first")
            return
        if not self.targets:
            return
        self.targets.pop(index if 0 <= index < len(self.targets) else -1)
        self._targets_changed()

    def _targets_changed(self) -> None:
        self.accuracy = {}
        self.profile.targets = list(self.targets)
        self._emit("targets_changed", list(self.targets))

    # ------------------------------------------------------------------ sweeps
    def start_sweep(self, name: str = "sweep") -> bool:
        """Start recording a sweep called ``name`` (every frame from now, raw and head-corrected)."""
        from tonguevis.live.sweeps import Sweep, SweepError

        if self.last_frame is None:
            self.say("no frames yet: connect to a source first")
            return False
        names = self.slot_names(self.last_frame.n_sensors)
        try:
            self.sweep = Sweep(name, names, profile=self.profile, targets=list(self.targets),
                               axes=getattr(self.source, "axes", None))
        except (SweepError, TargetError) as exc:
            self._emit("error", f"cannot start the sweep: {exc}")
            return False
        self.accuracy = {}
        self._emit("sweep_changed", f"recording sweep {self.sweep.number} ({self.sweep.name})…")
        return True

    def stop_sweep(self):
        """Stop the sweep and save it into the profile's folder; returns the SavedSweep (None if nothing saved)."""
        from tonguevis.live.profiles import save_profile

        sweep, self.sweep = self.sweep, None
        if sweep is None:
            return None
        try:
            saved = sweep.save(profiles_root=self.profiles_root)
            save_profile(self.profile, self.profiles_root)
        except (TonguevisError, OSError) as exc:
            self._emit("sweep_changed", f"sweep {sweep.number} not saved: {exc}")
            self._emit("error", f"the sweep could not be saved: {exc}")
            return None
        self.last_saved = saved
        summaries = sweep.summaries()
        means = ", ".join(f"{s.mean_percent:.0f} %" for s in summaries) if summaries else "no targets"
        self._emit("sweep_changed", f"sweep {sweep.number} ({sweep.name}): {sweep.n_samples} frames, "
                                    f"{sweep.elapsed_s:.1f} s, accuracy {means}; saved in {saved.folder}")
        return saved

    def _add_to_sweep(self, frame, corrected) -> None:
        """``frame`` into the sweep (``corrected``: its head-corrected slots, None without a simulation)."""
        from tonguevis.live.sweeps import SweepError

        sweep = self.sweep
        try:
            if sweep._live_correction is False:
                corrected = None
            elif sweep._live_correction and corrected is None:
                return  # the simulation stopped mid-sweep: keep the sweep consistent (raw only from before)
            self.accuracy = dict(enumerate(sweep.add_frame(frame, corrected=corrected)))
        except SweepError as exc:
            self.say(f"sweep: frame {frame.frame} not added ({exc})")
        if sweep.finished:
            self.stop_sweep()
