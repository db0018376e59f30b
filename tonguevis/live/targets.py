"""Biofeedback targets as clinics use them, and how well a sensor hits them.

The kinds follow Opti-Speech's conventions (``/work/shared/LIVE.md``, facts only):

* :class:`StaticTarget` -- a point and a radius.
* :class:`OscillatingTarget` -- moves between two points at a frequency (Hz),
  sinusoidally by default (``shape="sine"``: at ``a`` at its start, at ``b`` half a
  period later, easing in and out as a real articulation does) or at constant speed
  (``shape="linear"``: a triangle wave between the same two points).
* :class:`FollowingTarget` -- follows a sensor (a landmark) at a fixed offset.
* :class:`ReplayTarget` -- replays one sensor's motion from an earlier sweep or
  production (speed, reverse, offset, looped by default); it keeps the production's
  times, and optionally the production's other sensors, so a caller can draw the whole
  "ghost tongue" the patient imitates (:meth:`ReplayTarget.production_time`,
  :meth:`ReplayTarget.ghost_at`).

Units: positions in **metres** (tonguevis's :class:`~tonguevis.io.recording.Recording`
uses metres), times in seconds on the sweep's clock (0 at the sweep's start),
frequencies in Hz, accuracy in percent.  Convert to mm only for display.

Accuracy of a sample, exactly as Opti-Speech defines it: with ``d`` the distance from the
scored sensor to the target's centre and ``r`` the radius, 100 % when ``d <= r``, 0 % when
``d >= 2 r``, ``100 (2 r - d) / r`` between (:func:`accuracy_percent`).  A sample whose
sensor or target position is missing (NaN) has no accuracy: it is left out of every mean
and counted (:class:`AccuracySummary.n_missing`).

Cycles (:func:`cycle_period`): the least common multiple of the periodic targets'
periods.  Static and following targets, and replays that do not loop, have no period and
do not constrain the cycle.  Periods are taken as exact fractions of a second when they
are (to 1 part in 10^9) ratios with a denominator of at most 1000 (any frequency given
to three decimals, 1/3 s, 10/17 s ...); their LCM is the cycle when it is at most
``max_cycle_s`` (10 s by default).  Otherwise the periods are not commensurate in any
useful sense (1 Hz and 1.01 Hz repeat together only after 100 s), and the cycle is the
**longest** period instead, said in :attr:`CyclePlan.reason`.  With no periodic target
there are no cycles (per-sweep figures only) unless the caller gives a period.

Every target has the ``sensor`` it scores (a sensor name, e.g. ``"TT"``), a ``radius``
(metres, at least :data:`MIN_RADIUS_M` = 1 mm: the NDI Wave's accuracy is about 0.5 to
1 mm (Berry 2011), so a smaller target means nothing) and an ``opacity`` for the views.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, Mapping, Sequence

import numpy as np

from tonguevis.errors import TonguevisError

#: The smallest radius a target may have (m): the NDI Wave's own error is up to 1 mm for 98 % of samples.
MIN_RADIUS_M = 1e-3
#: A radius larger than this (m) is not a tongue target: almost surely millimetres given as metres.
MAX_RADIUS_M = 0.1
#: Periods are exact fractions of a second with at most this denominator (see the module docstring).
PERIOD_DENOMINATOR = 1000
#: Cycles longer than this (s) are not useful feedback; the longest period is used instead.
MAX_CYCLE_S = 10.0
#: Colour of a sample with no accuracy (grey).
MISSING_COLOUR = (0.5, 0.5, 0.5)


class TargetError(TonguevisError):
    """A biofeedback target is impossible or cannot be scored."""


# --------------------------------------------------------------------------- accuracy


def accuracy_percent(distance, radius: float) -> np.ndarray:
    """Opti-Speech's accuracy (%) of samples at ``distance`` (m, any shape) from a target of ``radius`` (m).

    100 inside the radius (``d <= r``), 0 at one radius outside it and beyond (``d >= 2 r``),
    ``100 (2 r - d) / r`` between.  NaN distances stay NaN.
    """
    d = np.asarray(distance, dtype=float)
    return 100.0 * np.clip((2.0 * radius - d) / radius, 0.0, 1.0)


def accuracy_colour(accuracy) -> np.ndarray:
    """RGB floats in [0, 1] for accuracy values in percent (any shape -> shape + (3,)).

    Red at 0 %, yellow at 50 %, green at 100 % (the traffic-light map clinicians read at a
    glance; it is not kind to red-green colour blindness, which the numbers beside it are).
    NaN (no accuracy: the sensor is missing) is grey, :data:`MISSING_COLOUR`.
    """
    a = np.asarray(accuracy, dtype=float) / 100.0
    a_clipped = np.clip(np.nan_to_num(a, nan=0.0), 0.0, 1.0)
    rgb = np.stack([np.minimum(1.0, 2.0 * (1.0 - a_clipped)), np.minimum(1.0, 2.0 * a_clipped),
                    np.zeros_like(a_clipped)], axis=-1)
    rgb[np.isnan(a)] = MISSING_COLOUR
    return rgb


# --------------------------------------------------------------------------- targets


def _point(value, what: str) -> np.ndarray:
    p = np.asarray(value, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise TargetError(f"{what} must be three finite coordinates in metres, got {value!r}")
    return p


def _check_radius(radius: float) -> float:
    try:
        r = float(radius)
    except (TypeError, ValueError):
        raise TargetError(f"a target's radius must be a number of metres, got {radius!r}") from None
    if not math.isfinite(r) or r < MIN_RADIUS_M:
        raise TargetError(
            f"a target's radius must be at least {MIN_RADIUS_M * 1000:g} mm ({MIN_RADIUS_M} m), got {r!r} m: "
            "the NDI Wave measures to about 0.5-1 mm (Berry 2011), so a smaller target means nothing")
    if r > MAX_RADIUS_M:
        raise TargetError(f"a target's radius of {r:g} m is not a tongue target (radii are in metres: "
                          f"did you mean {r / 1000:g} m, i.e. {r:g} mm?)")
    return r


def _check_opacity(opacity: float) -> float:
    try:
        o = float(opacity)
    except (TypeError, ValueError):
        raise TargetError(f"a target's opacity must be a number between 0 and 1, got {opacity!r}") from None
    if not 0.0 <= o <= 1.0:
        raise TargetError(f"a target's opacity must be between 0 and 1, got {opacity!r}")
    return o


def _times(t) -> tuple[np.ndarray, bool]:
    """(N,) float times and whether ``t`` was a scalar."""
    arr = np.asarray(t, dtype=float)
    return np.atleast_1d(arr), arr.ndim == 0


@dataclass(eq=False)
class Target:
    """Base of every target: the sensor it scores, its radius (m), its opacity and a name."""

    sensor: str
    radius: float
    opacity: float
    name: str

    kind = "target"

    def _check_common(self) -> None:
        if not isinstance(self.sensor, str) or not self.sensor:
            raise TargetError(f"a target needs the name of the sensor it scores, got {self.sensor!r}")
        self.radius = _check_radius(self.radius)
        self.opacity = _check_opacity(self.opacity)
        self.name = str(self.name) if self.name else f"{self.kind} on {self.sensor}"

    @property
    def period(self) -> float | None:
        """Seconds after which the target's motion repeats, or None (it does not, or does not move)."""
        return None

    @property
    def sensors_needed(self) -> tuple[str, ...]:
        """Names of the sensors :meth:`position_at` and :meth:`score` need."""
        return (self.sensor,)

    def _positions(self, t: np.ndarray, sensors: Mapping[str, np.ndarray] | None) -> np.ndarray:
        raise NotImplementedError

    def position_at(self, t, sensors: Mapping[str, Any] | None = None) -> np.ndarray:
        """Centre of the target (m) at times ``t`` (s, sweep clock).

        t : a float (returns (3,)) or (N,) times (returns (N, 3)).
        sensors : name -> positions (m) at the same times, (N, 3) (or (3,) for a scalar
            ``t``); only :class:`FollowingTarget` needs it.
        """
        times, scalar = _times(t)
        if sensors is not None and scalar:
            sensors = {k: np.atleast_2d(np.asarray(v, dtype=float)) for k, v in sensors.items()}
        p = self._positions(times, sensors)
        return p[0] if scalar else p

    def score(self, t, sensors: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
        """(distance (m), accuracy (%)) of the scored sensor at times ``t``; NaN where missing.

        sensors : name -> (N, 3) positions (m) at times ``t`` (N,), the scored sensor among
            them (with any per-sensor offset already applied).
        """
        times, scalar = _times(t)
        if self.sensor not in sensors:
            raise TargetError(f"target {self.name!r} scores sensor {self.sensor!r}, which is not streamed "
                              f"(sensors: {', '.join(sensors) or 'none'})")
        if scalar:
            sensors = {k: np.atleast_2d(np.asarray(v, dtype=float)) for k, v in sensors.items()}
        xyz = np.asarray(sensors[self.sensor], dtype=float)
        if xyz.shape != (len(times), 3):
            raise TargetError(f"sensor {self.sensor!r}: positions of shape {xyz.shape} for {len(times)} times")
        centre = self._positions(times, sensors)
        distance = np.linalg.norm(xyz - centre, axis=1)
        acc = accuracy_percent(distance, self.radius)
        return (distance[0], acc[0]) if scalar else (distance, acc)

    def to_dict(self) -> dict:
        """JSON-ready description (metres, seconds, Hz); :func:`target_from_dict` reads it back."""
        return {"kind": self.kind, "name": self.name, "sensor": self.sensor, "radius_m": self.radius,
                "opacity": self.opacity}


@dataclass(eq=False)
class StaticTarget(Target):
    """A sphere of ``radius`` (m) at ``point`` (m), scoring ``sensor``."""

    point: np.ndarray = None

    kind = "static"

    def __init__(self, point, radius: float, sensor: str = "TT", opacity: float = 0.5, name: str = ""):
        self.sensor, self.radius, self.opacity, self.name = sensor, radius, opacity, name
        self.point = _point(point, "a static target's point")
        self._check_common()

    def _positions(self, t, sensors):
        return np.broadcast_to(self.point, (len(t), 3)).copy()

    def to_dict(self) -> dict:
        return {**super().to_dict(), "point_m": self.point.tolist()}


@dataclass(eq=False)
class OscillatingTarget(Target):
    """A sphere moving between ``a`` and ``b`` (m) at ``frequency_hz``.

    shape : ``"sine"`` (default): ``a + (b - a) (1 - cos(2 pi f (t - start_s))) / 2``, at ``a``
        at ``start_s`` and every period after, at ``b`` half a period later, slowing at both
        ends; ``"linear"``: at constant speed between them (a triangle wave, same instants).
    start_s : when (s, sweep clock) the target is at ``a``.
    """

    a: np.ndarray = None
    b: np.ndarray = None
    frequency_hz: float = 1.0
    shape: str = "sine"
    start_s: float = 0.0

    kind = "oscillating"
    SHAPES = ("sine", "linear")

    def __init__(self, a, b, frequency_hz: float, radius: float, sensor: str = "TT", opacity: float = 0.5,
                 name: str = "", shape: str = "sine", start_s: float = 0.0):
        self.sensor, self.radius, self.opacity, self.name = sensor, radius, opacity, name
        self.a = _point(a, "an oscillating target's point a")
        self.b = _point(b, "an oscillating target's point b")
        f = float(frequency_hz)
        if not math.isfinite(f) or f <= 0:
            raise TargetError(f"an oscillating target's frequency must be a positive number of Hz, got {frequency_hz!r}")
        self.frequency_hz = f
        if shape not in self.SHAPES:
            raise TargetError(f"an oscillating target's shape must be one of {', '.join(self.SHAPES)}, got {shape!r}")
        self.shape = shape
        self.start_s = float(start_s)
        self._check_common()

    @property
    def period(self) -> float:
        return 1.0 / self.frequency_hz

    def fraction(self, t) -> np.ndarray:
        """Where between ``a`` (0) and ``b`` (1) the target is at times ``t`` (s)."""
        phase = np.mod((np.asarray(t, dtype=float) - self.start_s) * self.frequency_hz, 1.0)
        if self.shape == "sine":
            return 0.5 * (1.0 - np.cos(2.0 * np.pi * phase))
        return 1.0 - np.abs(1.0 - 2.0 * phase)

    def _positions(self, t, sensors):
        return self.a + self.fraction(t)[:, None] * (self.b - self.a)

    def to_dict(self) -> dict:
        return {**super().to_dict(), "a_m": self.a.tolist(), "b_m": self.b.tolist(),
                "frequency_hz": self.frequency_hz, "shape": self.shape, "start_s": self.start_s}


@dataclass(eq=False)
class FollowingTarget(Target):
    """A sphere at sensor ``follows``'s position plus ``offset`` (m), scoring ``sensor``.

    E.g. a target 10 mm above the jaw sensor that the tongue tip should reach.  Missing
    (NaN) wherever ``follows`` is missing.
    """

    follows: str = ""
    offset: np.ndarray = None

    kind = "following"

    def __init__(self, follows: str, offset, radius: float, sensor: str = "TT", opacity: float = 0.5,
                 name: str = ""):
        self.sensor, self.radius, self.opacity, self.name = sensor, radius, opacity, name
        if not isinstance(follows, str) or not follows:
            raise TargetError(f"a following target needs the name of the sensor it follows, got {follows!r}")
        self.follows = follows
        self.offset = _point(offset, "a following target's offset")
        self._check_common()

    @property
    def sensors_needed(self) -> tuple[str, ...]:
        return (self.sensor, self.follows)

    def _positions(self, t, sensors):
        if sensors is None or self.follows not in sensors:
            raise TargetError(f"target {self.name!r} follows sensor {self.follows!r}, which is not given "
                              f"(sensors: {', '.join(sensors or ()) or 'none'})")
        xyz = np.asarray(sensors[self.follows], dtype=float)
        if xyz.shape != (len(t), 3):
            raise TargetError(f"sensor {self.follows!r}: positions of shape {xyz.shape} for {len(t)} times")
        return xyz + self.offset

    def to_dict(self) -> dict:
        return {**super().to_dict(), "follows": self.follows, "offset_m": self.offset.tolist()}


@dataclass(eq=False)
class ReplayTarget(Target):
    """A sphere replaying one sensor's recorded motion (a production of an earlier sweep).

    times : (K,) s, increasing, the production's own clock (kept as recorded, so the
        production's other sensors can be looked up at :meth:`production_time`).
    positions : (K, 3) m, the replayed sensor (NaN where it was missing).
    speed : how fast the replay runs (2 = twice as fast); > 0.
    reverse : play the production backwards.
    offset : (3,) m added to every replayed position (e.g. to shift the template to a
        patient's smaller mouth).
    loop : repeat the production (default); else the target stays at the production's last
        (first when reversed) position after it ends, and has no period.
    start_s : when (s, sweep clock) the replay starts; before it the target is at its
        first position.
    template : optional name -> (K, 3) m of the production's other sensors at the same
        times: the ghost tongue (:meth:`ghost_at`).

    A looped replay's period is ``(times[-1] - times[0]) / speed``: the production runs from
    its first to its last sample and starts again at once.
    """

    times: np.ndarray = None
    positions: np.ndarray = None
    speed: float = 1.0
    reverse: bool = False
    offset: np.ndarray = None
    loop: bool = True
    start_s: float = 0.0
    template: dict = field(default_factory=dict)

    kind = "replay"

    def __init__(self, times, positions, radius: float, sensor: str = "TT", speed: float = 1.0,
                 reverse: bool = False, offset=(0.0, 0.0, 0.0), loop: bool = True, start_s: float = 0.0,
                 opacity: float = 0.5, name: str = "", template: Mapping[str, Any] | None = None):
        self.sensor, self.radius, self.opacity, self.name = sensor, radius, opacity, name
        self.times = np.asarray(times, dtype=float)
        self.positions = np.asarray(positions, dtype=float)
        k = len(self.times)
        if self.times.ndim != 1 or k < 2:
            raise TargetError(f"a replay target needs at least two sample times, got shape {self.times.shape}")
        if not np.all(np.isfinite(self.times)) or not np.all(np.diff(self.times) > 0):
            raise TargetError("a replay target's times must be finite and increasing")
        if self.positions.shape != (k, 3):
            raise TargetError(f"a replay target's positions must be ({k}, 3) metres, got {self.positions.shape}")
        if not np.any(np.all(np.isfinite(self.positions), axis=1)):
            raise TargetError("a replay target's recorded sensor is missing in every sample")
        s = float(speed)
        if not math.isfinite(s) or s <= 0:
            raise TargetError(f"a replay target's speed must be a positive number, got {speed!r}")
        self.speed, self.reverse, self.loop = s, bool(reverse), bool(loop)
        self.offset = _point(offset, "a replay target's offset")
        self.start_s = float(start_s)
        self.template = {}
        for name_, xyz in (template or {}).items():
            arr = np.asarray(xyz, dtype=float)
            if arr.shape != (k, 3):
                raise TargetError(f"replay template sensor {name_!r}: shape {arr.shape}, expected ({k}, 3)")
            self.template[str(name_)] = arr
        self._check_common()

    @classmethod
    def from_recording(cls, recording, sensor: str, radius: float, start_s: float | None = None,
                       end_s: float | None = None, scored: str | None = None, **options) -> "ReplayTarget":
        """Replay ``recording``'s ``sensor`` between ``start_s`` and ``end_s`` (its own clock, s).

        The recording's other sensors become the ghost ``template``; the target scores
        ``scored`` (default the same sensor name).  ``options`` go to the constructor.
        """
        if sensor not in recording.sensors:
            raise TargetError(f"the recording has no sensor {sensor!r} (it has {', '.join(recording.sensors)})",
                              recording.metadata.get("file"))
        t = np.asarray(recording.times, dtype=float)
        keep = np.ones(len(t), bool)
        if start_s is not None:
            keep &= t >= start_s
        if end_s is not None:
            keep &= t <= end_s
        template = {n: np.asarray(p)[keep] for n, p in recording.sensors.items()}
        return cls(t[keep], template[sensor], radius, sensor=scored or sensor, template=template, **options)

    @property
    def duration(self) -> float:
        """Length of the production (s, its own clock)."""
        return float(self.times[-1] - self.times[0])

    @property
    def period(self) -> float | None:
        return self.duration / self.speed if self.loop else None

    def production_time(self, t) -> np.ndarray:
        """The production's own time (s) that the replay shows at sweep times ``t`` (s)."""
        elapsed = np.maximum((np.asarray(t, dtype=float) - self.start_s) * self.speed, 0.0)
        if self.loop:
            elapsed = np.mod(elapsed, self.duration)
        else:
            elapsed = np.minimum(elapsed, self.duration)
        return self.times[-1] - elapsed if self.reverse else self.times[0] + elapsed

    def _interp(self, xyz: np.ndarray, pt: np.ndarray) -> np.ndarray:
        # np.interp per axis: a NaN sample makes the target missing next to it, as the sensor was.
        return np.stack([np.interp(pt, self.times, xyz[:, i]) for i in range(3)], axis=1)

    def _positions(self, t, sensors):
        return self._interp(self.positions, self.production_time(t)) + self.offset

    def ghost_at(self, t) -> dict[str, np.ndarray]:
        """The ghost tongue at sweep times ``t``: name -> (N, 3) m (or (3,) for a scalar ``t``) of
        every template sensor, shifted by ``offset`` like the target."""
        times, scalar = _times(t)
        pt = self.production_time(times)
        out = {n: self._interp(xyz, pt) + self.offset for n, xyz in self.template.items()}
        return {n: p[0] for n, p in out.items()} if scalar else out

    def to_dict(self) -> dict:
        return {**super().to_dict(), "times_s": self.times.tolist(), "positions_m": _nan_list(self.positions),
                "speed": self.speed, "reverse": self.reverse, "offset_m": self.offset.tolist(), "loop": self.loop,
                "start_s": self.start_s, "template_m": {n: _nan_list(p) for n, p in self.template.items()}}


def _nan_list(array: np.ndarray) -> list:
    """Nested lists with NaN as None (JSON has no NaN)."""
    return [[None if not math.isfinite(v) else v for v in row] for row in np.asarray(array, float).tolist()]


def _nan_array(value, what: str) -> np.ndarray:
    try:
        return np.array([[np.nan if v is None else v for v in row] for row in value], dtype=float)
    except (TypeError, ValueError) as exc:
        raise TargetError(f"{what}: not rows of three numbers ({exc})") from None


TARGET_KINDS = {cls.kind: cls for cls in (StaticTarget, OscillatingTarget, FollowingTarget, ReplayTarget)}


def target_from_dict(d: Mapping[str, Any]) -> Target:
    """The target :meth:`Target.to_dict` described; TargetError when a field is missing or wrong."""
    if not isinstance(d, Mapping):
        raise TargetError(f"a target must be a JSON object, got {type(d).__name__}")
    kind = d.get("kind")
    if kind not in TARGET_KINDS:
        raise TargetError(f"unknown target kind {kind!r} (known: {', '.join(TARGET_KINDS)})")
    try:
        common = {"radius": d["radius_m"], "sensor": d["sensor"], "opacity": d.get("opacity", 0.5),
                  "name": d.get("name", "")}
        if kind == "static":
            return StaticTarget(d["point_m"], **common)
        if kind == "oscillating":
            return OscillatingTarget(d["a_m"], d["b_m"], d["frequency_hz"], shape=d.get("shape", "sine"),
                                     start_s=d.get("start_s", 0.0), **common)
        if kind == "following":
            return FollowingTarget(d["follows"], d["offset_m"], **common)
        return ReplayTarget(d["times_s"], _nan_array(d["positions_m"], "replay positions_m"),
                            speed=d.get("speed", 1.0), reverse=d.get("reverse", False),
                            offset=d.get("offset_m", (0.0, 0.0, 0.0)), loop=d.get("loop", True),
                            start_s=d.get("start_s", 0.0),
                            template={n: _nan_array(p, f"replay template {n}")
                                      for n, p in (d.get("template_m") or {}).items()}, **common)
    except KeyError as exc:
        raise TargetError(f"{kind} target lacks the field {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        if isinstance(exc, TargetError):
            raise
        raise TargetError(f"{kind} target: bad value ({exc})") from None


# --------------------------------------------------------------------------- cycles and sweeps


@dataclass
class CyclePlan:
    """How a sweep is cut into cycles: ``period_s`` (None: no cycles), whether it is the exact LCM, and why."""

    period_s: float | None
    exact: bool
    reason: str


def _as_fraction(period: float) -> Fraction | None:
    f = Fraction(period).limit_denominator(PERIOD_DENOMINATOR)
    return f if f > 0 and abs(float(f) - period) <= 1e-9 * period else None


def cycle_period(targets: Sequence[Target], max_cycle_s: float = MAX_CYCLE_S) -> CyclePlan:
    """The cycle of ``targets``: the LCM of their periods (see the module docstring for the rules)."""
    periods = [t.period for t in targets if t.period is not None and t.period > 0]
    if not periods:
        return CyclePlan(None, True, "no target repeats (static, following or unlooped replay): per-sweep figures only")
    fractions = [_as_fraction(p) for p in periods]
    longest = max(periods)
    if all(f is not None for f in fractions):
        num = math.lcm(*(f.numerator for f in fractions))
        den = math.gcd(*(f.denominator for f in fractions))
        lcm = num / den
        if lcm <= max_cycle_s * (1 + 1e-12):
            return CyclePlan(lcm, True, f"least common multiple of the periods {_seconds(periods)}")
        why = f"their least common multiple ({lcm:g} s) is longer than {max_cycle_s:g} s"
    else:
        why = "they are not commensurate (not ratios of whole numbers with a denominator up to 1000)"
    return CyclePlan(longest, False, f"the periods {_seconds(periods)}: {why}, so each cycle is the longest "
                                     f"period ({longest:g} s)")


def _seconds(periods) -> str:
    return ", ".join(f"{p:g} s" for p in periods)


@dataclass
class AccuracySummary:
    """Accuracy of one target over some samples.

    mean_percent : mean accuracy (%) of the samples with one (NaN when none has).
    hit_fraction : share of those samples inside the radius (accuracy 100 %), 0-1 (NaN when none).
    n_samples : samples with an accuracy; n_missing : samples left out (sensor or target missing).
    """

    mean_percent: float
    hit_fraction: float
    n_samples: int
    n_missing: int

    def to_dict(self) -> dict:
        return {"mean_percent": _json_float(self.mean_percent), "hit_fraction": _json_float(self.hit_fraction),
                "n_samples": self.n_samples, "n_missing": self.n_missing}


def _json_float(v: float):
    return None if not math.isfinite(v) else float(v)


def summarise(accuracy) -> AccuracySummary:
    """:class:`AccuracySummary` of (N,) accuracy values (%), NaN samples left out and counted."""
    acc = np.asarray(accuracy, dtype=float).ravel()
    ok = np.isfinite(acc)
    n = int(ok.sum())
    if n == 0:
        return AccuracySummary(float("nan"), float("nan"), 0, int(acc.size))
    return AccuracySummary(float(acc[ok].mean()), float(np.mean(acc[ok] >= 100.0)), n, int(acc.size - n))


@dataclass
class Cycle:
    """One cycle: ``index`` from 0, ``start_s``/``end_s`` (sweep clock), whether all of it was recorded,
    and one :class:`AccuracySummary` per target (same order as the targets)."""

    index: int
    start_s: float
    end_s: float
    complete: bool
    targets: list[AccuracySummary]


def per_cycle(times, accuracies: np.ndarray, period_s: float, start_s: float = 0.0) -> list[Cycle]:
    """Cut samples into cycles of ``period_s`` from ``start_s`` and summarise each target in each.

    times : (N,) s, sweep clock.  accuracies : (N, T) %, one column per target (NaN missing).
    Cycle k holds the samples with ``start_s + k period <= t < start_s + (k + 1) period``;
    samples before ``start_s`` belong to no cycle.  A cycle is ``complete`` when the samples
    reach both its ends (the first sample within one sample step of its start, the last within
    one step of its end); the sweep's last, cut-short cycle is not.
    """
    t = np.asarray(times, dtype=float)
    acc = np.asarray(accuracies, dtype=float)
    if acc.ndim == 1:
        acc = acc[:, None]
    if acc.shape[0] != len(t):
        raise TargetError(f"{len(t)} times but {acc.shape[0]} rows of accuracy")
    if period_s is None or not period_s > 0:
        raise TargetError(f"a cycle's period must be a positive number of seconds, got {period_s!r}")
    if len(t) == 0:
        return []
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    index = np.floor((t - start_s) / period_s + 1e-9).astype(np.int64)
    cycles = []
    for k in np.unique(index[index >= 0]):
        rows = index == k
        lo, hi = start_s + k * period_s, start_s + (k + 1) * period_s
        tk = t[rows]
        complete = bool(tk[0] - lo <= step + 1e-9 and hi - tk[-1] <= step + 1e-9)
        cycles.append(Cycle(int(k), float(lo), float(hi), complete,
                            [summarise(acc[rows, j]) for j in range(acc.shape[1])]))
    return cycles


def score_targets(targets: Sequence[Target], times, sensors: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(distance (N, T) m, accuracy (N, T) %) of every target over a sweep's samples.

    times : (N,) s, sweep clock.  sensors : name -> (N, 3) m (offsets applied, head-corrected).
    """
    t = np.asarray(times, dtype=float)
    n = len(t)
    dist = np.full((n, len(targets)), np.nan)
    acc = np.full((n, len(targets)), np.nan)
    for j, target in enumerate(targets):
        dist[:, j], acc[:, j] = target.score(t, sensors)
    return dist, acc
