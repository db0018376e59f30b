"""Which articulator makes a CV syllable's consonant, and its constriction signal.

The place of articulation decides the sensor: the tongue tip (TT) for /t d n s z l r/,
the dorsum (TD) for /k g/, the lips (their aperture, from UL and LL) for /p b m/.
When the syllable is named (argument, the recording's metadata, or a token of the file
name such as ``spk1_ka`` or ``OSN12_Kah``) its place wins; otherwise the data decide:
the tip, unless the dorsum's or the lips' closures are at least ``DOMINANCE`` times as
large (a /k/ dorsum rises 2.4-3 times as far as the tip on real /ka/ sessions, the tip
1-1.2 times the dorsum on /ta/).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording
from tonguevis.preprocess.gestures import find_closures, lowpass, signal_range

#: Consonant letter -> place of articulation.
PLACES = {**dict.fromkeys("tdnszlr", "tip"), **dict.fromkeys("kgq", "dorsum"), **dict.fromkeys("pbmw", "lips")}
#: Place -> the articulator (a sensor name, or LA for the lip aperture).
ARTICULATOR_OF_PLACE = {"tip": "TT", "dorsum": "TD", "lips": "LA"}
#: Another articulator replaces the tip when its closures are this many times the tip's.
DOMINANCE = 2.0
LIP_APERTURE = "LA"
_SYLLABLE = re.compile(r"^([bcdfgklmnpqrstvwz]{1,2})h?([aeiou]{1,2})h?$", re.IGNORECASE)


def syllable_from_name(path) -> str | None:
    """A CV syllable named by a token of the file's stem (``spk1_ka`` -> ``ka``,
    ``006_OSN12_Kah_nofb`` -> ``ka``), lower case; None when no token is one."""
    if not path:
        return None
    tokens = re.split(r"[^A-Za-z0-9]+", Path(str(path)).stem)
    for token in tokens:
        match = _SYLLABLE.match(token)
        if match:
            return (match.group(1) + match.group(2)).lower()
    return None


def place_of(syllable: str | None) -> str | None:
    """The place of articulation of a syllable's first consonant ("tip", "dorsum", "lips") or None."""
    if not syllable:
        return None
    letters = [c for c in syllable.lower() if c.isalpha()]
    for c in letters:
        if c in PLACES:
            return PLACES[c]
        if c in "aeiou":
            return None
    return None


def available(rec: Recording) -> list[str]:
    """The articulators of ``rec`` there are signals for: TT, TD, and LA with UL and LL."""
    out = [name for name in ("TT", "TD") if name in rec.sensors]
    if "UL" in rec.sensors and "LL" in rec.sensors:
        out.append(LIP_APERTURE)
    return out


@dataclass
class ConstrictionSignal:
    """One articulator's motion, low-passed: ``signal`` (N,) rises as it closes (metres);
    ``positions`` (N, 3) metres (the lower lip for the lips); ``speed`` (N,) m/s,
    the tangential speed (for the lips: of the aperture)."""

    articulator: str
    signal: np.ndarray
    positions: np.ndarray
    speed: np.ndarray
    valid: np.ndarray

    @property
    def scale(self) -> float:
        return signal_range(self.signal)


def constriction_signal(rec: Recording, articulator: str, axis: int = 2) -> ConstrictionSignal:
    """The constriction signal of ``articulator`` (a sensor name, or LA for the lips)."""
    file = rec.metadata.get("file")
    if articulator == LIP_APERTURE:
        if "UL" not in rec.sensors or "LL" not in rec.sensors:
            raise RecordingError("the lip aperture needs UL and LL sensors "
                                 f"(sensors: {', '.join(rec.sensor_names)})", file)
        upper = lowpass(rec.sensors["UL"], rec.rate)
        lower = lowpass(rec.sensors["LL"], rec.rate)
        aperture = np.linalg.norm(upper - lower, axis=1)
        valid = np.isfinite(rec.sensors["UL"]).all(axis=1) & np.isfinite(rec.sensors["LL"]).all(axis=1)
        speed = np.abs(np.gradient(aperture, 1.0 / rec.rate)) if len(aperture) > 1 else np.zeros_like(aperture)
        return ConstrictionSignal(articulator, -aperture, lower, speed, valid)
    if articulator not in rec.sensors:
        raise RecordingError(f"no sensor {articulator!r} to find the productions on "
                             f"(sensors: {', '.join(rec.sensor_names)}); name the channels with --sensors MAP "
                             "or pick another with --articulator", file)
    raw = rec.sensors[articulator]
    positions = lowpass(raw, rec.rate)
    velocity = np.gradient(positions, 1.0 / rec.rate, axis=0) if len(positions) > 1 else np.zeros_like(positions)
    return ConstrictionSignal(articulator, positions[:, axis].copy(), positions, np.linalg.norm(velocity, axis=1),
                              np.isfinite(raw).all(axis=1))


def _typical_size(signal: ConstrictionSignal, rate: float) -> tuple[float, int]:
    if not signal.valid.any():
        return 0.0, 0
    closures, _ = find_closures(signal.signal, rate)
    if not closures:
        return 0.0, 0
    return float(np.median([c.size for c in closures])), len(closures)


def choose_articulator(rec: Recording, syllable: str | None = None) -> tuple[str, str]:
    """(articulator, why): from the syllable's place when known, else from the data."""
    names = available(rec)
    file = rec.metadata.get("file")
    if not names:
        raise RecordingError("no tongue-tip (TT), dorsum (TD) or lip (UL+LL) sensors to find productions on "
                             f"(sensors: {', '.join(rec.sensor_names)}); name the channels with --sensors MAP",
                             file)
    told = syllable or rec.metadata.get("syllable")
    source = "named"
    if not told:
        told = syllable_from_name(file)
        source = "from the file name"
    place = place_of(told)
    if place is not None and ARTICULATOR_OF_PLACE[place] in names:
        articulator = ARTICULATOR_OF_PLACE[place]
        return articulator, f"/{told}/ ({source}): the {place} ({articulator})"
    sizes = {name: _typical_size(constriction_signal(rec, name), rec.rate) for name in names}
    base = "TT" if "TT" in sizes else max(sizes, key=lambda n: sizes[n][0])
    best = base
    for name, (size, count) in sizes.items():
        if name != base and count >= 2 and size >= DOMINANCE * sizes[base][0] and size > sizes[best][0]:
            best = name
    described = ", ".join(f"{n} {1000 * s:.1f} mm" for n, (s, _) in sizes.items())
    if best == base:
        return best, f"from the data: typical closing movement {described}"
    return best, (f"from the data: {best}'s closing movements are {sizes[best][0] / max(sizes[base][0], 1e-12):.1f} "
                  f"times {base}'s ({described})")
