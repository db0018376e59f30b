"""Small hand-made recordings for the preprocessing tests."""

from __future__ import annotations

import numpy as np

from tonguevis.io.recording import Audio, Recording


def recording(sensors: dict, rate: float = 100.0, audio=None) -> Recording:
    n = len(next(iter(sensors.values())))
    return Recording(rate=rate, times=np.arange(n) / rate, sensors={k: np.asarray(v, float) for k, v in sensors.items()},
                     audio=audio, metadata={"format": "test", "file": None, "original_unit": "m"})


def random_rotations(rng, n: int) -> np.ndarray:
    """(n, 3, 3) proper rotations from normalised random quaternions."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def syllable_train_recording(syllables=5, trains=3, rate=100.0, with_audio=True, seed=0,
                             noise=5e-5, period=0.26):
    """A tongue tip raised once per syllable (Gaussian bumps), trains separated by rest.

    syllables : per train, or a list of counts, one per train.
    TT z = A * sum_k exp(-(t - r_k)^2 / (2 sigma^2)) with sigma = 50 ms: the
    bumps barely overlap, so the maxima (releases) sit at r_k and the minima
    (vowels) midway between.  Audio: a 150 Hz tone from 50 ms before the first
    release to 150 ms after the last.  Returns (recording, true releases per
    train, audio spans (start, end) per train).
    """
    rng = np.random.default_rng(seed)
    amp, sigma = 0.008, 0.05
    counts = list(syllables) if isinstance(syllables, (list, tuple)) else [syllables] * trains
    starts = 3.0 + np.concatenate([[0.0], np.cumsum([c * period + 1.5 for c in counts[:-1]])])
    releases = [[t0 + k * period for k in range(c)] for t0, c in zip(starts, counts)]
    duration = releases[-1][-1] + 1.5
    n = int(round(duration * rate))
    t = np.arange(n) / rate
    centres = np.concatenate(releases)
    z = amp * np.exp(-((t[:, None] - centres[None, :]) ** 2) / (2 * sigma**2)).sum(axis=1)
    tip = np.column_stack([np.zeros(n), np.zeros(n), z]) + rng.normal(0, noise, (n, 3))
    spans = [(r[0] - 0.05, r[-1] + 0.15) for r in releases]
    audio = None
    if with_audio:
        arate = 8000.0
        ta = np.arange(int(round(duration * arate))) / arate
        samples = rng.normal(0, 1e-4, ta.size)
        for a, b in spans:
            m = (ta >= a) & (ta < b)
            samples[m] += 0.3 * np.sin(2 * np.pi * 150 * ta[m])
        audio = Audio(samples=samples, rate=arate)
    return recording({"TT": tip}, rate=rate, audio=audio), releases, spans


def bump_release_times(releases, sigma: float = 0.05, fraction: float = 0.2) -> list[list[float]]:
    """Where the noise-free tip of :func:`syllable_train_recording` has come down ``fraction``
    of the way from each bump's top to the lowest point before the next bump (or 0.4 s on):
    the release as tonguevis and the shared hand labels define it, from a 0.1 ms grid."""
    centres = np.concatenate(releases)
    t = np.arange(0.0, centres[-1] + 1.0, 1e-4)
    z = np.exp(-((t[:, None] - centres[None, :]) ** 2) / (2 * sigma**2)).sum(axis=1)
    out = []
    for train in releases:
        row = []
        for k, top in enumerate(train):
            stop = train[k + 1] if k + 1 < len(train) else top + 0.4
            span = (t >= top) & (t <= stop)
            peak = np.argmax(np.where(span, z, -np.inf))
            low = z[span].min()
            falling = (t > t[peak]) & (z <= z[peak] - fraction * (z[peak] - low))
            row.append(float(t[np.argmax(falling)]))
        out.append(row)
    return out


def isolated_ta_session(n=10, period=2.0, rest=10.0, dip=7.5, closure=11.0, vowel=0.0, rate=100.0) -> Recording:
    """A clinic session of ``n`` isolated /ta/ (DATA.md's description of the Opti-Speech sessions): the tip
    rests high (``rest`` mm), dips briefly (``dip``), rises fast to the closure (``closure``), falls far to
    the vowel (``vowel``) and slowly returns to rest, every ``period`` s; the other sensors follow it.
    The rise from the dip is 0.32 of the tip's range, its fall the whole range: every syllable clear."""
    from scipy.interpolate import PchipInterpolator

    keys = [(0.0, rest)]
    for k in range(n):
        t0 = 1.0 + k * period
        keys += [(t0, rest), (t0 + 0.10, dip), (t0 + 0.22, closure), (t0 + 0.30, closure), (t0 + 0.50, vowel),
                 (t0 + 0.65, vowel), (t0 + 1.35, rest)]
    keys.append((1.0 + n * period + 0.5, rest))
    t, z = np.array(keys).T
    times = np.arange(0.0, t[-1], 1.0 / rate)
    height = PchipInterpolator(t, z)(times) / 1000.0

    def at(x, y, up):
        return np.column_stack([np.full_like(times, x), np.full_like(times, y), up])

    sensors = {"TT": at(-0.01, 0.0, height), "TB": at(-0.02, 0.0, 0.6 * height), "TD": at(-0.04, 0.0, 0.3 * height),
               "TL": at(-0.02, 0.01, 0.5 * height), "TR": at(-0.02, -0.01, 0.5 * height),
               "JAW": at(0.0, 0.0, -0.03 + 0.3 * (height - rest / 1000.0))}
    return Recording(rate=rate, times=times, sensors=sensors,
                     metadata={"format": "test", "file": None, "original_unit": "m"})
