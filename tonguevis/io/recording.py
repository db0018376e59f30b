"""The one container every EMA reader returns: :class:`Recording`."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np


@dataclass
class Audio:
    """A mono audio track.

    samples : (K,) float32, nominally in [-1, 1] (float32 holds 16- and 24-bit PCM exactly,
        and halves a long session's sound: 30 minutes at 16 kHz are 115 MB, not 230).
    rate : samples per second (Hz).
    offset : time in seconds of ``samples[0]`` on the recording's clock.
    """

    samples: np.ndarray
    rate: float
    offset: float = 0.0

    def __post_init__(self) -> None:
        self.samples = np.asarray(self.samples, dtype=np.float32)

    @property
    def duration(self) -> float:
        """Length in seconds."""
        return len(self.samples) / float(self.rate)

    @property
    def times(self) -> np.ndarray:
        """(K,) sample times in seconds on the recording's clock."""
        return self.offset + np.arange(len(self.samples)) / float(self.rate)


@dataclass
class Label:
    """A time-aligned annotation (a word or a phone), times in seconds."""

    start: float
    end: float
    text: str
    tier: str = "words"


@dataclass
class Recording:
    """EMA sensor motion with optional audio and labels.

    Attributes
    ----------
    rate : float
        Sensor sample rate in Hz.
    times : (N,) float64
        Sample times in seconds.
    sensors : dict[str, (N, 3) float64]
        Positions in metres, in the tonguevis frame (x anterior, y left, z up)
        when the format says how its axes lie, else in the device frame (the
        reader documents which).  NaN where a sample is invalid.
    orientations : dict[str, (N, k) float64]
        Per-sensor orientation when the format has it (quaternions w, x, y, z
        for NDI Wave; angles in degrees for Carstens/MVIEW), NaN where invalid.
    audio : Audio or None
    labels : list[Label]
    metadata : dict
        At least ``format``, ``file`` and ``original_unit``; readers add
        ``dropped_frames`` (list of (time_s, n_missing)), ``synthetic`` and
        format specifics.
    """

    rate: float
    times: np.ndarray
    sensors: dict[str, np.ndarray]
    orientations: dict[str, np.ndarray] = field(default_factory=dict)
    audio: Audio | None = None
    labels: list[Label] = field(default_factory=list)
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def n_samples(self) -> int:
        return int(len(self.times))

    @property
    def duration(self) -> float:
        """Seconds from the first to one period past the last sample."""
        if self.n_samples == 0:
            return 0.0
        return float(self.times[-1] - self.times[0] + 1.0 / self.rate)

    @property
    def sensor_names(self) -> list[str]:
        return list(self.sensors)

    def valid(self, name: str) -> np.ndarray:
        """(N,) bool: samples of sensor ``name`` with all three coordinates finite."""
        return np.all(np.isfinite(self.sensors[name]), axis=1)

    def valid_fraction(self, name: str) -> float:
        if self.n_samples == 0:
            return 0.0
        return float(np.mean(self.valid(name)))

    def with_sensors(self, sensors: dict[str, np.ndarray], **changes: Any) -> "Recording":
        """A copy with other sensor arrays (and any other field changed)."""
        return replace(self, sensors=sensors, **changes)

    def on_uniform_grid(self) -> "Recording":
        """A copy whose frames are uniform in time: frames lost in gaps come back as NaN samples.

        Frame k is at ``times[0] + k / rate``; returns ``self`` when nothing was
        dropped (see ``metadata['dropped_frames']``).
        """
        from tonguevis.io._common import regrid_dropped_frames

        return regrid_dropped_frames(self)

    def renamed(self, mapping: dict[str, str]) -> "Recording":
        """A copy with sensors renamed ``old -> new`` (others keep their names)."""
        rename = lambda d: {mapping.get(k, k): v for k, v in d.items()}  # noqa: E731
        return replace(self, sensors=rename(self.sensors), orientations=rename(self.orientations))


def unstated_axes_note(recording: Recording, short: bool = False) -> str | None:
    """What to tell the user when ``recording``'s positions are in the device's own axes (else None).

    Readers of formats that do not say how their axes lie (NDI Wave, Carstens,
    EST_Track without ``axes=``) set ``metadata['frame'] = 'device'``; tonguevis
    then takes the device's x as anterior, y as left and z as up.  ``short``: the
    few words of the app's status bar; else the sentence of ``tonguevis info``.
    """
    if recording.metadata.get("frame") != "device":
        return None
    if short:
        return "axes not stated in the file: taken as x anterior, y left, z up"
    return ("the file does not state its axes: the positions are in the recording device's own frame, taken as "
            "x anterior, y left, z up. If the tongue comes out turned, state them with -O axes=... (e.g. "
            "-O axes=-y,x,z), an \"axes\" entry in the sensor_map.json beside the file, or convert the file "
            "(tonguevis convert FILE OUT.csv -O axes=...)")
