"""Energy-time curves of CV productions (§6.3, Figs. 13-14).

The elastic energy U = ½ qᵀΛq (eq. 6) of every frame is a one-number
"pseudo-shape" metric: each production becomes a curve U(t), and curves of many
trials and speakers overlay on one time axis.  A production runs from one
consonant release to the next (:func:`tonguevis.preprocess.find_productions`);
its curve is given on absolute time (seconds since the production's release)
and on normalised time (0 at the release, 1 at the next release) so that
productions of different durations line up.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np

from tonguevis.errors import TonguevisError

#: Grouping keys an :class:`EnergyCurve` carries.
GROUP_KEYS = ("recording", "speaker", "syllable", "trial", "train", "index")


class EnergyError(TonguevisError):
    """Energy curves asked of inconsistent inputs."""


def modal_energy(q: np.ndarray, eigenvalues: np.ndarray) -> np.ndarray:
    """(F,) elastic energy U = ½ qᵀΛq in joules for q (F, m) and Λ's diagonal (m,) in s⁻².

    The modes are mass-normalised, so q is in m·kg^½ and Λ q² is in J.
    """
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    lam = np.asarray(eigenvalues, dtype=np.float64)
    if q.shape[1] != lam.shape[0]:
        raise EnergyError(f"q has {q.shape[1]} modes but {lam.shape[0]} eigenvalues were given")
    return 0.5 * np.einsum("fm,m,fm->f", q, lam, q)


@dataclass
class EnergyCurve:
    """U(t) over one production.

    recording : name of the recording (file stem); speaker, syllable, trial :
        the corpus labels (empty/0 when unknown); train, index : the
        production's train and 1-based position in it; production : a label
        ``"<train>.<index>"``.
    times : (k,) seconds on the recording's clock of the frames inside the production.
    time_s : (k,) seconds since the curve's start (the consonant release; the
        previous vowel for vowel-to-vowel windows).
    time_norm : (k,) in [0, 1]: (t - start) / (end - start).
    energy : (k,) joules.
    frames : (k,) frame indices into the motion.
    start, end : the curve's span (s, recording clock).
    extra : ``release_s`` (the consonant release, s) when the span knows it.
    """

    recording: str
    speaker: str
    syllable: str
    trial: int
    train: int
    index: int
    times: np.ndarray
    time_s: np.ndarray
    time_norm: np.ndarray
    energy: np.ndarray
    frames: np.ndarray
    start: float
    end: float
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def production(self) -> str:
        return f"{self.train}.{self.index}"

    @property
    def duration(self) -> float:
        """Seconds."""
        return self.end - self.start

    def label(self, key: str) -> Any:
        """The value of a grouping key (one of :data:`GROUP_KEYS`)."""
        if key not in GROUP_KEYS:
            raise EnergyError(f"unknown grouping key {key!r}; choose from {', '.join(GROUP_KEYS)}")
        return getattr(self, key)

    def resampled(self, n: int = 101) -> np.ndarray:
        """(n,) energy (J) linearly interpolated on the uniform normalised grid 0..1."""
        return np.interp(np.linspace(0.0, 1.0, n), self.time_norm, self.energy)

    def stats(self) -> dict[str, float]:
        """Peak (J), its time (s since the start, and normalised), area (J·s), duration (s)."""
        k = int(np.argmax(self.energy))
        area = float(np.trapezoid(self.energy, self.time_s)) if len(self.energy) > 1 else 0.0
        return {
            "peak_J": float(self.energy[k]),
            "peak_time_s": float(self.time_s[k]),
            "peak_time_norm": float(self.time_norm[k]),
            "area_Js": area,
            "mean_J": float(self.energy.mean()),
            "duration_s": float(self.duration),
        }


def production_curves(
    motion,
    productions: Iterable,
    recording: str = "",
    speaker: str = "",
    syllable: str = "",
    trial: int = 0,
) -> list[EnergyCurve]:
    """One :class:`EnergyCurve` per production of ``motion``.

    motion : a :class:`~tonguevis.sim.Motion` (uses ``times`` and ``energy``).
    productions : objects with ``train``, ``index``, ``start``, ``end`` (s), e.g.
        a :class:`~tonguevis.preprocess.ProductionTable` or :func:`vowel_windows`;
        a production's ``label`` is the curve's syllable when ``syllable`` is empty.
    A production keeps the frames with start <= t <= end; one with fewer than
    two frames inside the motion raises :class:`EnergyError`.
    """
    times = np.asarray(motion.times, dtype=np.float64)
    energy = np.asarray(motion.energy, dtype=np.float64)
    curves = []
    for p in productions:
        start, end = float(p.start), float(p.end)
        lo = np.searchsorted(times, start, side="left")
        hi = np.searchsorted(times, end, side="right")
        frames = np.arange(lo, hi)
        if end <= start or len(frames) < 2:
            raise EnergyError(
                f"{recording or 'motion'}: production {p.train}.{p.index} ({start:.3f}-{end:.3f} s) "
                f"holds {len(frames)} frame(s) of a motion spanning {times[0]:.3f}-{times[-1]:.3f} s")
        t = times[frames]
        curves.append(EnergyCurve(
            recording=recording, speaker=speaker, syllable=syllable or getattr(p, "label", ""), trial=int(trial),
            train=int(p.train), index=int(p.index), times=t, time_s=t - start,
            time_norm=(t - start) / (end - start), energy=energy[frames], frames=frames,
            start=start, end=end,
            extra={"release_s": float(p.release)} if hasattr(p, "release") else {},
        ))
    return curves


@dataclass(frozen=True)
class Window:
    """A span of a production for its curve: ``start``/``end`` in s, ``release`` its consonant release."""

    train: int
    index: int
    start: float
    end: float
    release: float


def vowel_windows(productions: Iterable) -> list[Window]:
    """Vowel-to-vowel spans with the consonant in the middle.

    Production k's window runs from the vowel of production k − 1 of the same
    train to its own vowel, so the consonant closure and release fall inside
    rather than at the edges (as a release-to-release production has them).
    The first production of a train has no window.  ``productions`` must hold
    every production of the trains (``find_productions(..., keep=None)``).
    """
    prods = list(productions)
    previous = {(p.train, p.index): p for p in prods}
    out = []
    for p in prods:
        before = previous.get((p.train, p.index - 1))
        if before is not None and p.vowel > before.vowel:
            out.append(Window(p.train, p.index, float(before.vowel), float(p.vowel), float(p.release)))
    return out


@dataclass
class GroupSummary:
    """Statistics of the curves of one group.

    key : the group's labels (tuple, one per grouping key); n : curves;
    mean / std : per statistic of :meth:`EnergyCurve.stats` (same names);
    grid : (G,) normalised time; mean_curve / std_curve : (G,) J on that grid.
    """

    key: tuple
    n: int
    mean: dict[str, float]
    std: dict[str, float]
    grid: np.ndarray
    mean_curve: np.ndarray
    std_curve: np.ndarray


def group_curves(curves: Sequence[EnergyCurve], by: Sequence[str] = ("speaker", "syllable")) -> dict[tuple, list[EnergyCurve]]:
    """Curves grouped by the labels ``by`` (keys of :data:`GROUP_KEYS`), in first-seen order."""
    groups: dict[tuple, list[EnergyCurve]] = {}
    for c in curves:
        groups.setdefault(tuple(c.label(k) for k in by), []).append(c)
    return groups


def summarize(curves: Sequence[EnergyCurve], by: Sequence[str] = ("speaker", "syllable"),
              grid_points: int = 101) -> list[GroupSummary]:
    """Peak, time of peak, area (mean and standard deviation) and the mean curve per group."""
    out = []
    grid = np.linspace(0.0, 1.0, grid_points)
    for key, members in group_curves(curves, by).items():
        table = [c.stats() for c in members]
        names = list(table[0])
        values = np.array([[row[k] for k in names] for row in table])
        resampled = np.stack([c.resampled(grid_points) for c in members])
        std = values.std(axis=0, ddof=1) if len(members) > 1 else np.zeros(len(names))
        out.append(GroupSummary(
            key=key, n=len(members),
            mean=dict(zip(names, values.mean(axis=0).tolist())),
            std=dict(zip(names, std.tolist())),
            grid=grid, mean_curve=resampled.mean(axis=0),
            std_curve=resampled.std(axis=0, ddof=1) if len(members) > 1 else np.zeros(grid_points),
        ))
    return out


CSV_COLUMNS = ("recording", "production", "time_s", "time_norm", "energy_J",
               "speaker", "syllable", "trial", "train", "index", "recording_time_s", "frame")


def curves_to_rows(curves: Sequence[EnergyCurve]) -> list[tuple]:
    """Long-format rows, one per frame of each curve, in the order of :data:`CSV_COLUMNS`."""
    rows = []
    for c in curves:
        for k in range(len(c.energy)):
            rows.append((c.recording, c.production, f"{c.time_s[k]:.6f}", f"{c.time_norm[k]:.6f}",
                         f"{c.energy[k]:.9e}", c.speaker, c.syllable, c.trial, c.train, c.index,
                         f"{c.times[k]:.6f}", int(c.frames[k])))
    return rows


def write_curves_csv(curves: Sequence[EnergyCurve], path) -> None:
    """Write the curves as long-format CSV (:data:`CSV_COLUMNS`); temporary file, then rename."""
    import csv

    from tonguevis._files import atomic_write

    def write(tmp):
        with open(tmp, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(CSV_COLUMNS)
            writer.writerows(curves_to_rows(curves))

    atomic_write(path, write)


def write_summary_csv(summaries: Sequence[GroupSummary], by: Sequence[str], path) -> None:
    """One row per group: the keys, n, then mean and std of each statistic."""
    import csv

    from tonguevis._files import atomic_write

    stats = list(summaries[0].mean) if summaries else []
    header = [*by, "n"] + [f"{s}_{kind}" for s in stats for kind in ("mean", "std")]

    def write(tmp):
        with open(tmp, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(header)
            for g in summaries:
                writer.writerow([*g.key, g.n] + [f"{v:.6g}" for s in stats for v in (g.mean[s], g.std[s])])

    atomic_write(path, write)
