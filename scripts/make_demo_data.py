#!/usr/bin/env python
"""Write the SYNTHETIC demo corpus of tonguevis to ``data/``.

Three made-up speakers each say five-syllable trains of /ta/, /ka/, /la/ and
/ra/ (five trains per file, after 5 s of rest), recorded as an NDI Wave
system would: 100 Hz sensor positions in a TSV export plus a 16 kHz WAV.
Nothing here was measured on a person.

Sensors (NDI Ids as in the 'paper' preset, ``data/sensor_map.json``): REF1 (0,
6DOF head reference behind the left ear), TT (1, midline 10 mm behind the
tongue tip), TD (2, midline 30 mm behind the tip), TL / TR (3 / 4, 20 mm behind
the tip, left and right), JAW (5, lower gum at the mandibular symphysis), REF2
(6, nasion), REF3 (7, upper incisor gum).  Positions are in the tonguevis
frame (x anterior, y left, z up), millimetres in the file, origin at the
upper incisor edge.

Motion: a gestural model.  Each articulator (every tongue sensor relative to
the jaw, and the jaw) moves as a critically damped second-order system,
x'' = -2 w x' - w^2 (x - target(t)), towards targets switched at consonant
and vowel onsets (closed form: a sum of step responses 1 - (1 + w t) e^{-w t}).
The jaw translates (opening 5-9 mm for /a/), the head sways slightly (rigid,
< 1 degree and ~1 mm), and every coordinate gets Gaussian noise of 0.15 mm.
Audio: a glottal pulse train through formant resonators (source-filter), a
noise burst at each stop release, timed on the simulated tongue-tip release.

The true times of every production (release to release, §3.2 of Yang et al.
2013, on the consonant's articulator: the dorsum for /k/, the tip otherwise; the
release where it has come down 20 % of the way from the closure to the vowel) go to ``data/demo_truth.json``; tests hold the segmentation
to them.  The output is deterministic (fixed seeds).

Run: ``python scripts/make_demo_data.py [--out data]``.

For scale tests, ``--speakers N --out DIR`` writes a larger synthetic corpus
(N speakers x 4 syllables; the first three are the demo speakers, the others
are drawn from seeded ranges around them, each with its own habits), and
``--trains K`` / ``--syllables ta,ka`` make shorter or fewer files.  Such
corpora are for benchmarks and tests: write them outside the repository.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tonguevis.io.recording import Audio, Recording  # noqa: E402

SENSOR_RATE = 100.0
AUDIO_RATE = 16000
FINE_RATE = 2000.0  # grid on which the true times are computed
REST_S = 5.0
PAUSE_S = 1.1
TAIL_S = 0.8
TRAINS = 5
SYLLABLES_PER_TRAIN = 5
NOISE_MM = 0.15
SYLLABLES = ("ta", "ka", "la", "ra")

# NDI Ids of the 'paper' preset (tonguevis/presets/paper.json).
NDI_IDS = {"REF1": 0, "TT": 1, "TD": 2, "TL": 3, "TR": 4, "JAW": 5, "REF2": 6, "REF3": 7}
TONGUE = ("TT", "TD", "TL", "TR")

# Rest positions (mm, head frame, origin at the upper incisor edge).  The
# tongue tip itself rests at TIP; the paper's rhombus is measured from it.
# The paper puts TL/TR 1 cm in from the edges; our tongue is ~20 mm wide 20 mm
# behind the tip, so 1 cm in from each edge would put both on the midline: we
# place them 6-7 mm off the midline (the spacing real layouts show).
TIP = np.array([-9.0, 0.0, -13.0])
BASE_LAYOUT = {
    "TT": TIP + [-10.0, 0.0, 3.0],
    "TD": TIP + [-30.0, 0.0, 8.0],
    "TL": TIP + [-20.0, 6.0, 5.0],
    "TR": TIP + [-20.0, -6.0, 5.0],
    "JAW": np.array([-3.0, 0.0, -24.0]),
    "REF1": np.array([-85.0, 62.0, -18.0]),
    "REF2": np.array([22.0, 0.0, 48.0]),
    "REF3": np.array([-1.0, 0.0, 9.0]),
}

# Gesture targets (mm) relative to rest: tongue sensors relative to the jaw,
# the jaw relative to the head.  x anterior, y left, z up.
TARGETS = {
    "a": {"TT": (-1.0, 0, -4.0), "TD": (-3.0, 0, -5.0), "TL": (-1.5, 0, -4.5), "TR": (-1.5, 0, -4.5),
          "JAW": (-2.0, 0, -7.0)},
    "t": {"TT": (3.0, 0, 9.0), "TD": (0.0, 0, 2.0), "TL": (1.0, 0, 4.0), "TR": (1.0, 0, 4.0),
          "JAW": (0.5, 0, -1.0)},
    "k": {"TT": (-1.0, 0, 5.0), "TD": (-1.0, 0, 10.0), "TL": (-0.5, 0, 4.5), "TR": (-0.5, 0, 4.5),
          "JAW": (0.0, 0, -1.5)},
    "l": {"TT": (2.0, 0, 9.0), "TD": (-1.0, 0, -1.0), "TL": (0.0, -0.7, -3.0), "TR": (0.0, 0.7, -3.0),
          "JAW": (0.0, 0, -2.0)},
    "r": {"TT": (-4.0, 0, 6.0), "TD": (-2.0, 0, 5.0), "TL": (-2.0, 0, 3.0), "TR": (-2.0, 0, 3.0),
          "JAW": (0.0, 0, -2.5)},
}
ARTICULATORS = ("TT", "TD", "TL", "TR", "JAW")

SPEAKERS = {
    "spk1": dict(
        description="typical: symmetric, regular timing",
        seed=1001, period=0.27, consonant_share=0.42, jaw_open=1.0, omega={"tongue": 40.0, "TT": 40.0, "JAW": 30.0},
        f0=(125.0, 105.0), formants_a=(730, 1090, 2440), k_dorsum=1.0, tip_jitter=0.0, timing_jitter=0.0,
        lateral_gain=(1.0, 1.0), layout_shift={"TL": (0, 0, 0), "TR": (0, 0, 0)},
    ),
    "spk2": dict(
        description="weaker /k/ dorsum peak (half the dorsum raise), slower rate",
        seed=2002, period=0.29, consonant_share=0.42, jaw_open=0.8, omega={"tongue": 38.0, "TT": 38.0, "JAW": 28.0},
        f0=(215.0, 185.0), formants_a=(850, 1220, 2810), k_dorsum=0.5, tip_jitter=0.0, timing_jitter=0.0,
        lateral_gain=(1.0, 1.0), layout_shift={"TL": (0, 1.0, 0), "TR": (0, -1.0, 0)},
    ),
    "spk3": dict(
        description="asymmetric laterals (left moves more), less controlled tongue tip "
                    "(amplitude and timing jitter, lateral wobble, slower tip)",
        seed=3003, period=0.26, consonant_share=0.42, jaw_open=1.2, omega={"tongue": 40.0, "TT": 33.0, "JAW": 30.0},
        f0=(112.0, 96.0), formants_a=(700, 1150, 2500), k_dorsum=1.0, tip_jitter=0.2, timing_jitter=0.012,
        lateral_gain=(1.4, 0.7), layout_shift={"TL": (0, 1.5, 0), "TR": (0, 0.5, 0)},
    ),
}

CONSONANT_FORMANTS = {"l": (360, 1000, 2800), "r": (420, 1100, 1600)}
BURST_BAND = {"t": (3500.0, 1200.0), "k": (1900.0, 600.0)}  # centre, bandwidth (Hz)
VOT = {"t": 0.035, "k": 0.045}


def file_seed(speaker: str, syllable: str) -> int:
    return SPEAKERS[speaker]["seed"] + 17 * SYLLABLES.index(syllable)


# ---------------------------------------------------------------- gestures
def step_responses(t: np.ndarray, onsets: np.ndarray, steps: np.ndarray, omega: float):
    """Critically damped responses to target steps.

    t (T,) s; onsets (J,) s; steps (J, D) target changes.  Returns position
    (T, D) and velocity (T, D) (units of steps, per second).
    """
    lag = t[:, None] - onsets[None, :]
    on = lag > 0
    wl = omega * np.where(on, lag, 0.0)
    decay = np.exp(-wl)
    h = np.where(on, 1.0 - (1.0 + wl) * decay, 0.0)
    dh = np.where(on, omega * wl * decay, 0.0)
    return h @ steps, dh @ steps


def schedule(speaker: str, syllable: str, rng: np.random.Generator, n_trains: int = TRAINS):
    """Gesture onsets: list of trains, each a list of (c_onset, v_onset) plus the return onset."""
    p = SPEAKERS[speaker]
    jitter = p["timing_jitter"]
    trains, t = [], REST_S
    for _ in range(n_trains):
        syllables = []
        for k in range(SYLLABLES_PER_TRAIN):
            stretch = 1.25 if k in (0, SYLLABLES_PER_TRAIN - 1) else 1.0  # edges are longer (§3.2)
            period = p["period"] * stretch
            c_dur = p["consonant_share"] * period + (rng.uniform(-jitter, jitter) if jitter else 0.0)
            v_dur = period - p["consonant_share"] * period + (rng.uniform(-jitter, jitter) if jitter else 0.0)
            syllables.append((t, t + c_dur))
            t += c_dur + v_dur
        trains.append({"syllables": syllables, "return": t})
        t += PAUSE_S
    duration = trains[-1]["return"] + TAIL_S
    return trains, duration


def targets_for(speaker: str, consonant: str, scale: float, rng: np.random.Generator) -> dict:
    """Consonant targets of one syllable for every articulator (mm)."""
    p = SPEAKERS[speaker]
    out = {}
    for name in ARTICULATORS:
        target = np.array(TARGETS[consonant][name], dtype=float)
        if name != "JAW":
            target = target * scale
        if consonant == "k" and name == "TD":
            target[2] *= p["k_dorsum"]
        if name == "TT" and p["tip_jitter"]:
            target *= 1.0 + np.clip(rng.normal(0, p["tip_jitter"]), -0.35, 0.35)
            target[1] += rng.normal(0, 1.0)  # the tip wobbles sideways
        out[name] = target
    return out


def vowel_targets(speaker: str, scale: float) -> dict:
    p = SPEAKERS[speaker]
    out = {name: np.array(TARGETS["a"][name], dtype=float) * (1.0 if name == "JAW" else scale)
           for name in ARTICULATORS}
    out["JAW"] = out["JAW"] * p["jaw_open"]
    return out


def articulator_events(speaker: str, syllable: str, trains, rng):
    """{articulator: (onsets (J,), steps (J, 3))} for the whole file."""
    consonant = syllable[0]
    events = {name: ([], []) for name in ARTICULATORS}
    for train in trains:
        previous = {name: np.zeros(3) for name in ARTICULATORS}
        for k, (c_on, v_on) in enumerate(train["syllables"]):
            scale = 1.15 if k in (0, SYLLABLES_PER_TRAIN - 1) else 1.0
            for onset, goal in ((c_on, targets_for(speaker, consonant, scale, rng)),
                                (v_on, vowel_targets(speaker, scale))):
                for name in ARTICULATORS:
                    events[name][0].append(onset)
                    events[name][1].append(goal[name] - previous[name])
                    previous[name] = goal[name]
        for name in ARTICULATORS:
            events[name][0].append(train["return"])
            events[name][1].append(-previous[name])
    p = SPEAKERS[speaker]
    left, right = p["lateral_gain"]
    out = {}
    for name, (onsets, steps) in events.items():
        steps = np.array(steps)
        if name == "TL":
            steps = steps * left
        elif name == "TR":
            steps = steps * right
        out[name] = (np.array(onsets), steps)
    return out


def omega_of(speaker: str, name: str) -> float:
    omega = SPEAKERS[speaker]["omega"]
    return omega.get(name, omega["tongue"])


def head_frame_motion(speaker: str, events, t: np.ndarray):
    """Noise-free positions (mm, head frame) and the TT vertical velocity (mm/s) at times t."""
    jaw, jaw_v = step_responses(t, *events["JAW"], omega_of(speaker, "JAW"))
    positions, velocity_z = {}, None
    shift = SPEAKERS[speaker]["layout_shift"]
    for name in ARTICULATORS:
        rest = BASE_LAYOUT[name] + np.asarray(shift.get(name, (0, 0, 0)), dtype=float)
        if name == "JAW":
            positions[name] = rest + jaw
            continue
        own, own_v = step_responses(t, *events[name], omega_of(speaker, name))
        positions[name] = rest + jaw + own
        if name == "TT":
            velocity_z = own_v[:, 2] + jaw_v[:, 2]
    for name in ("REF1", "REF2", "REF3"):
        positions[name] = np.broadcast_to(BASE_LAYOUT[name], (len(t), 3)).copy()
    return positions, velocity_z


def head_motion(t: np.ndarray, rng: np.random.Generator):
    """Slow rigid head sway: rotation (N,) Rotation and translation (N, 3) mm."""
    freqs = rng.uniform(0.06, 0.2, size=(2, 3))
    phases = rng.uniform(0, 2 * np.pi, size=(2, 3))
    angles = np.radians(0.7) * np.sin(2 * np.pi * freqs[0] * t[:, None] + phases[0])
    shift = 0.8 * np.sin(2 * np.pi * freqs[1] * t[:, None] + phases[1])
    return Rotation.from_rotvec(angles), shift


PIVOT = np.array([-80.0, 0.0, -60.0])  # roughly the atlanto-occipital joint (mm)


# ---------------------------------------------------------------- truth
def crossings(t: np.ndarray, v: np.ndarray, falling: bool) -> np.ndarray:
    """Times where v changes sign (+ to - if falling), linearly interpolated."""
    a, b = v[:-1], v[1:]
    idx = np.flatnonzero((a > 0) & (b <= 0)) if falling else np.flatnonzero((a < 0) & (b >= 0))
    return t[idx] + a[idx] / (a[idx] - b[idx]) * (t[idx + 1] - t[idx])


def tip_maxima(trains, acoustic, t_fine, v_fine):
    """Productions from the noise-free tip maxima: the times the audio is made from (its bursts sit at the
    tip's highest point; kept so that the committed sound does not change)."""
    releases = crossings(t_fine, v_fine, falling=True)
    vowels = crossings(t_fine, v_fine, falling=False)
    rows = []
    for number, (train, (_, end)) in enumerate(zip(trains, acoustic), start=1):
        first, last = train["syllables"][0][0], train["return"] + 0.1
        mine = releases[(releases > first) & (releases < last)]
        if len(mine) != SYLLABLES_PER_TRAIN:
            raise RuntimeError(f"train {number}: {len(mine)} tip maxima, expected {SYLLABLES_PER_TRAIN}")
        for index, release in enumerate(mine, start=1):
            stop = mine[index] if index < len(mine) else end
            vowel = vowels[(vowels > release) & (vowels < stop)]
            if len(vowel) != 1:
                raise RuntimeError(f"train {number} production {index}: {len(vowel)} vowel minima")
            rows.append({"train": number, "index": index, "start": float(release), "end": float(stop),
                         "release": float(release), "vowel": float(vowel[0])})
    return rows


#: The articulator whose closure opens each syllable: the place of its consonant.
CLOSING = {"t": "TT", "l": "TT", "r": "TT", "k": "TD"}
#: A release is where the closing articulator has come down this fraction of the way to the vowel.
RELEASE_FRACTION = 0.20


def true_productions(trains, acoustic, t_fine, z_fine):
    """Release-to-release productions of every train from the noise-free closing articulator.

    z_fine : its height (mm) at t_fine.  closure : its highest point (velocity zero
    crossing); vowel : the lowest point that follows; release : the first time after the
    closure at which it has come down 20 % of the way to the vowel (the rule of the
    shared hand labels); a production runs from its release to the next one (the last of
    a train to the train's acoustic end).
    """
    v_fine = np.gradient(z_fine, t_fine)
    closures = crossings(t_fine, v_fine, falling=True)
    vowels = crossings(t_fine, v_fine, falling=False)
    rows = []
    for number, (train, (_, end)) in enumerate(zip(trains, acoustic), start=1):
        first, last = train["syllables"][0][0], train["return"] + 0.1
        mine = closures[(closures > first) & (closures < last)]
        if len(mine) != SYLLABLES_PER_TRAIN:
            raise RuntimeError(f"train {number}: {len(mine)} closures, expected {SYLLABLES_PER_TRAIN}")
        found = []
        for index, closure in enumerate(mine):
            bound = mine[index + 1] if index + 1 < len(mine) else end + 0.5
            vowel = vowels[(vowels > closure) & (vowels < bound)]
            if len(vowel) != 1:
                raise RuntimeError(f"train {number} production {index + 1}: {len(vowel)} vowel minima")
            top, bottom = np.interp([closure, vowel[0]], t_fine, z_fine)
            falling = (t_fine > closure) & (z_fine <= top - RELEASE_FRACTION * (top - bottom))
            found.append((float(closure), float(t_fine[np.argmax(falling)]), float(vowel[0])))
        for index, (closure, release, vowel) in enumerate(found, start=1):
            stop = found[index][1] if index < len(found) else end
            rows.append({"train": number, "index": index, "start": release, "end": float(stop),
                         "release": release, "closure": closure, "vowel": vowel})
    return rows


# ---------------------------------------------------------------- audio
def resonators(x: np.ndarray, formants, bandwidths=(90.0, 110.0, 170.0)) -> np.ndarray:
    for f, bw in zip(formants, bandwidths):
        r = np.exp(-np.pi * bw / AUDIO_RATE)
        a = [1.0, -2.0 * r * np.cos(2 * np.pi * f / AUDIO_RATE), r * r]
        x = lfilter([1.0 - r], a, x)
    return x


def ramp_gain(t: np.ndarray, spans, rise: float = 0.006, fall: float = 0.006) -> np.ndarray:
    """Sum of trapezoids: 1 inside each (start, end), linear ramps of `rise`/`fall` s ending at the edges."""
    g = np.zeros_like(t)
    for start, end in spans:
        up = np.clip((t - start) / rise, 0.0, 1.0)
        down = np.clip((end - t) / fall, 0.0, 1.0)
        g = np.maximum(g, np.minimum(up, down))
    return g


def synthesize_audio(speaker: str, syllable: str, trains, productions, duration: float, rng):
    """16 kHz mono audio aligned with the gestures; returns (samples, acoustic train spans)."""
    p = SPEAKERS[speaker]
    consonant = syllable[0]
    n = int(round(duration * AUDIO_RATE))
    t = np.arange(n) / AUDIO_RATE
    out = rng.normal(0.0, 10 ** (-80 / 20), n)  # room noise, -80 dBFS
    spans = []
    by_train: dict[int, list] = {}
    for row in productions:
        by_train.setdefault(row["train"], []).append(row)
    vowel_spans, cons_spans, f0 = [], [], np.full(n, np.nan)
    for number, train in enumerate(trains, start=1):
        rows = by_train[number]
        offset = train["return"] + 0.05  # voicing stops as the tongue and jaw close
        onsets = [c for c, _ in train["syllables"]]
        for k, row in enumerate(rows):
            release = row["release"]
            next_closure = onsets[k + 1] + 0.04 if k + 1 < len(rows) else offset
            if consonant in VOT:
                vowel_spans.append((release + VOT[consonant], next_closure))
                burst_len = 0.012
                m = (t >= release) & (t < release + VOT[consonant])
                noise = rng.normal(0.0, 1.0, int(m.sum()))
                centre, bw = BURST_BAND[consonant]
                shaped = resonators(noise, (centre,), (bw,))
                shaped *= 0.12 / (np.std(shaped) + 1e-12)
                local = t[m] - release
                envelope = np.where(local < burst_len, 1.0, np.exp(-(local - burst_len) / 0.01) + 0.08)
                out[m] += shaped * envelope
            else:
                start = onsets[k] + 0.03 if k == 0 else release - 0.05
                cons_spans.append((start, release + 0.01))
                vowel_spans.append((release, next_closure))
        first = rows[0]["release"] if consonant in VOT else onsets[0] + 0.03
        spans.append((float(first), float(offset)))
        inside = (t >= first - 0.05) & (t <= offset + 0.05)
        f0[inside] = np.interp(t[inside], [first, offset], p["f0"])
    f0 = np.where(np.isfinite(f0), f0, p["f0"][1])
    f0 = f0 * (1.0 + 0.01 * np.sin(2 * np.pi * 5.0 * t))  # slight vibrato keeps it natural
    phase = np.cumsum(f0) / AUDIO_RATE
    pulses = np.diff(np.floor(phase), prepend=0.0)
    source = lfilter([1.0], [1.0, -1.9, 0.9025], pulses)  # glottal low-pass (-12 dB/oct)
    vowel = np.diff(resonators(source, p["formants_a"]), prepend=0.0)  # lip radiation
    vowel /= np.max(np.abs(vowel)) + 1e-12
    vowel_gain = ramp_gain(t, vowel_spans, fall=0.015)
    # The final vowel of each train fades as the jaw closes (last 60 ms).
    out += 0.45 * vowel * vowel_gain
    if cons_spans:
        cons = np.diff(resonators(source, CONSONANT_FORMANTS[consonant]), prepend=0.0)
        cons /= np.max(np.abs(cons)) + 1e-12
        out += 0.18 * cons * ramp_gain(t, cons_spans, rise=0.01, fall=0.01)
    return np.clip(out, -1.0, 1.0), spans


# ---------------------------------------------------------------- the recording
def synthesize(speaker: str, syllable: str, n_trains: int = TRAINS) -> tuple[Recording, dict]:
    """One demo file: the Recording (sensors named S<NDI Id>, metres) and its truth."""
    if speaker not in SPEAKERS or syllable not in SYLLABLES:
        raise ValueError(f"unknown speaker/syllable {speaker}/{syllable}")
    rng = np.random.default_rng(file_seed(speaker, syllable))
    trains, duration = schedule(speaker, syllable, rng, n_trains)
    events = articulator_events(speaker, syllable, trains, rng)
    n = int(round(duration * SENSOR_RATE))
    times = np.arange(n) / SENSOR_RATE
    t_fine = np.arange(int(round(duration * FINE_RATE))) / FINE_RATE
    fine, v_fine = head_frame_motion(speaker, events, t_fine)
    # Acoustic spans depend on the tip maxima; they do not depend on the audio.
    provisional = [(0.0, tr["return"] + 0.05) for tr in trains]
    samples, acoustic = synthesize_audio(speaker, syllable, trains, tip_maxima(trains, provisional, t_fine, v_fine),
                                         duration, rng)
    productions = true_productions(trains, acoustic, t_fine, fine[CLOSING[syllable[0]]][:, 2])
    positions, _ = head_frame_motion(speaker, events, times)
    rotation, shift = head_motion(times, rng)
    sensors = {}
    for name, xyz in positions.items():
        device = rotation.apply(xyz - PIVOT) + PIVOT + shift
        device += rng.normal(0.0, NOISE_MM, device.shape)
        # Whole micrometres, as the file holds them (and it compresses better).
        sensors[f"S{NDI_IDS[name]}"] = np.round(device, 3) / 1000.0
    sensors = dict(sorted(sensors.items(), key=lambda kv: int(kv[0][1:])))
    metadata = {
        "format": "ndi_wave", "file": None, "original_unit": "mm", "frame": "tonguevis",
        "synthetic": True, "generator": "scripts/make_demo_data.py", "speaker": speaker,
        "syllable": syllable,
    }
    rec = Recording(rate=SENSOR_RATE, times=times, sensors=sensors,
                    audio=Audio(samples=samples, rate=float(AUDIO_RATE)), metadata=metadata)
    truth = {
        "speaker": speaker, "syllable": syllable, "duration_s": duration,
        "rest_interval_s": [0.0, REST_S],
        "trains_s": [[round(a, 4), round(b, 4)] for a, b in acoustic],
        "productions": [{k: (round(v, 4) if isinstance(v, float) else v) for k, v in row.items()}
                        for row in productions],
    }
    return rec, truth


def generated_speaker(number: int) -> dict:
    """The habits of speaker ``spk<number>`` beyond the three demo speakers, drawn from seeded ranges around them."""
    rng = np.random.default_rng(7000 + number)
    tongue = rng.uniform(36.0, 42.0)
    f0 = rng.uniform(100.0, 220.0)
    formant_scale = rng.uniform(0.95, 1.17)
    tip_jitter = float(rng.uniform(0.0, 0.2)) if rng.random() < 0.3 else 0.0
    left, right = rng.uniform(0.8, 1.4), rng.uniform(0.7, 1.1)
    return dict(
        description=f"generated (seed {7000 + number}): left/right lateral gain {left:.2f}/{right:.2f}, "
                    f"tip jitter {tip_jitter:.2f}",
        seed=10_000 + 101 * number, period=rng.uniform(0.25, 0.30), consonant_share=rng.uniform(0.40, 0.44),
        jaw_open=rng.uniform(0.8, 1.2),
        omega={"tongue": tongue, "TT": tongue - rng.uniform(0.0, 6.0), "JAW": rng.uniform(27.0, 31.0)},
        f0=(f0, f0 * rng.uniform(0.84, 0.9)),
        formants_a=tuple(float(round(f * formant_scale)) for f in (730, 1090, 2440)),
        k_dorsum=rng.uniform(0.5, 1.0), tip_jitter=tip_jitter,
        timing_jitter=float(rng.uniform(0.0, 0.012)) if tip_jitter else 0.0,
        lateral_gain=(left, right),
        layout_shift={"TL": (0, rng.uniform(0.0, 1.5), 0), "TR": (0, rng.uniform(-1.0, 0.5), 0)},
    )


def speaker_names(count: int) -> list[str]:
    """``spk1`` .. ``spk<count>``; the ones beyond the demo speakers are added to SPEAKERS."""
    names = [f"spk{k}" for k in range(1, count + 1)]
    for k, name in enumerate(names, start=1):
        if name not in SPEAKERS:
            SPEAKERS[name] = generated_speaker(k)
    return names


def sensor_map_document() -> dict:
    layout = {name: [round(float(v), 2) for v in BASE_LAYOUT[name]] for name in NDI_IDS}
    return {
        "description": "SYNTHETIC demo corpus of tonguevis: which NDI Wave Id is which sensor "
                       "(the 'paper' preset). Rest positions are for spk1 in mm, tonguevis frame "
                       "(x anterior, y left, z up), origin at the upper incisor edge; the tongue tip "
                       f"itself rests at {TIP.tolist()}.",
        "format": "ndi_wave",
        "axes": "x,y,z",
        "axes_note": "the files' X, Y, Z are already ours (x anterior, y left, z up): readers take 'axes' as "
                     "their axes= option, so no command warns that the positions are in the device's frame",
        "sensors": dict(NDI_IDS),
        "placement": {
            "REF1": "6DOF head reference behind the left ear", "TT": "midline, 10 mm behind the tongue tip",
            "TD": "midline, 30 mm behind the tip", "TL": "left, 20 mm behind the tip, 6 mm off the midline",
            "TR": "right, 20 mm behind the tip, 6 mm off the midline",
            "JAW": "lower gum at the mandibular symphysis", "REF2": "nasion", "REF3": "upper incisor gum",
        },
        "rest_positions_mm": layout,
    }


def _write_json(path: Path, document) -> None:
    handle, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(handle, "w", encoding="utf-8") as out:
        json.dump(document, out, indent=1)
        out.write("\n")
    os.chmod(temp, 0o644)
    os.replace(temp, path)


DATA_README = """# SYNTHETIC demo corpus

Everything in this folder is made by `scripts/make_demo_data.py` (deterministic; rerun it to
rebuild). **It is synthetic: no person was recorded.** Tongue, jaw and head motion come from a
gestural model (critically damped movements towards consonant and vowel targets) and the audio
from a source-filter synthesis aligned with the gestures.

- `<speaker>_<syllable>.tsv` + `.wav`: NDI Wave TSV export layout (100 Hz, positions in mm in
  the tonguevis frame: x anterior, y left, z up; origin at the upper incisor edge) and 16 kHz
  mono audio. 5 s of rest, then five trains of five /ta/, /ka/, /la/ or /ra/ syllables.
- Speakers: `spk1` typical; `spk2` weaker /k/ dorsum peak, slower; `spk3` asymmetric laterals
  and a less controlled tongue tip.
- `sensor_map.json`: which NDI Id is which sensor (the 'paper' preset: REF1=0, TT=1, TD=2,
  TL=3, TR=4, JAW=5, REF2=6, REF3=7) with the rest positions. Read a file with
  `read_recording("data/spk1_ta.tsv", sensor_map="data/sensor_map.json")`.
- `demo_truth.json`: the true trains and productions (release to release, §3.2 of Yang et al.
  2013, on the consonant's articulator) of every file, in seconds, with each closure.
"""


def _write_text(path: Path, text: str) -> None:
    handle, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(handle, "w", encoding="utf-8") as out:
        out.write(text)
    os.chmod(temp, 0o644)
    os.replace(temp, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "data", help="output folder (default: data/)")
    parser.add_argument("--speakers", type=int, metavar="N",
                        help="a corpus of N speakers (default: the three demo speakers); beyond three they are "
                             "generated, each with its own habits")
    parser.add_argument("--trains", type=int, default=TRAINS, metavar="K",
                        help=f"five-syllable trains per file (default {TRAINS})")
    parser.add_argument("--syllables", default=",".join(SYLLABLES),
                        help=f"comma-separated, from {','.join(SYLLABLES)} (default: all)")
    args = parser.parse_args(argv)
    from tonguevis.io import write_recording

    syllables = [s.strip() for s in args.syllables.split(",") if s.strip()]
    if not syllables or any(s not in SYLLABLES for s in syllables):
        parser.error(f"--syllables: choose from {','.join(SYLLABLES)}")
    if args.trains < 1 or (args.speakers is not None and args.speakers < 1):
        parser.error("--speakers and --trains must be at least 1")
    demo = args.speakers is None and args.trains == TRAINS and syllables == list(SYLLABLES)
    speakers = list(SPEAKERS) if args.speakers is None else speaker_names(args.speakers)
    args.out.mkdir(parents=True, exist_ok=True)
    truth = {
        "synthetic": True,
        "note": "SYNTHETIC data made by scripts/make_demo_data.py (gestural model + source-filter audio); "
                "not a recording of a person. Times in seconds; productions run from one release "
                "to the next (the last of a train to the train's acoustic end), on the consonant's articulator "
                "(TD for /k/, TT otherwise); a release is where it has come down 20 % of the way from its closure "
                "(highest point) to the vowel (lowest point).",
        "sensor_rate_hz": SENSOR_RATE, "audio_rate_hz": AUDIO_RATE, "noise_mm": NOISE_MM,
        "speakers": {name: SPEAKERS[name]["description"] for name in speakers},
        "files": {},
    }
    for speaker in speakers:
        for syllable in syllables:
            rec, file_truth = synthesize(speaker, syllable, args.trains)
            name = f"{speaker}_{syllable}.tsv"
            write_recording(rec, args.out / name)
            truth["files"][name] = file_truth
            print(f"wrote {args.out / name} ({rec.duration:.1f} s)")
    _write_json(args.out / "demo_truth.json", truth)
    _write_text(args.out / "README.md", DATA_README if demo else (
        f"# SYNTHETIC corpus\n\nMade by `scripts/make_demo_data.py --speakers {len(speakers)} --trains {args.trains} "
        f"--syllables {','.join(syllables)}` (deterministic). **It is synthetic: no person was recorded.** "
        "The files are laid out as in the demo corpus; see the script's docstring.\n"))
    _write_json(args.out / "sensor_map.json", sensor_map_document())
    print(f"wrote {args.out / 'demo_truth.json'} and {args.out / 'sensor_map.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
