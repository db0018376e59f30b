#!/usr/bin/env python
"""A tongue sensor lost for 1 s on real recordings: the motion with the dropout against the motion without.

On the real Opti-Speech /ka/ (006) and /ta/ (009) of ../shared/data (never
copied here), each recording is simulated with the default settings; then one
tongue sensor (TB, then TD) is set to NaN for ``--seconds`` in the middle of
the speech, as a bad-status stretch of an NDI Wave export gives, and the
recording is simulated again with the rest interval the full run chose (so the
dropout cannot move the rest window), twice: as tonguevis does it now (the
sensor's spring in the projection of the targets weakened over 0.1 s and grown
back over 0.1 s, :mod:`tonguevis.sim.dropouts`) and as it did before (the sensor
released at once: ``engagement`` replaced by one that weights exactly the valid samples).

Per run: the largest volume change, the peak elastic energy, the largest node
displacement, the flagged frames (recovered + implausible) and the worst
frame-to-frame jump of the shape, max over nodes of |u(t+1) - 2u(t) + u(t-1)|,
from 0.2 s before the gap to 0.2 s after it (the same window in the run
without the dropout).  Writes a Markdown table (``--md``, default
docs/dropouts.md): summary figures only.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path
from unittest import mock

import numpy as np

from tonguevis.sim.dropouts import RAMP_S

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
RECORDINGS = {  # short name -> path under ../shared/data
    "/ka/ 006": ("ema", "optispeech", "006_OSN12_Kah_nofb_natural_take2_HR.tsv"),
    "/ta/ 009": ("ema", "optispeech", "009_OSN12_Tah_withFb_natural_HR.tsv"),
}
SENSORS = ("TB", "TD")
MARGIN_S = 0.2  # the jump is measured this long before and after the gap; the gap keeps this far from the rest


@contextlib.contextmanager
def released_at_once():
    """The behaviour before the handover: a missing sample releases its sensor in that very frame.

    Replaces the hook of :mod:`tonguevis.sim.dropouts` that ramps a lost sensor out and back
    (``engagement``: spring weights and anchors; ``handover`` in earlier versions: trust and acting)
    by one that follows the valid samples exactly.
    """
    from tonguevis.sim import dropouts

    def engagement(valid, rate, ramp_s=None):
        valid = np.asarray(valid, dtype=bool)
        frames = np.broadcast_to(np.arange(len(valid))[:, None], valid.shape).copy()
        return valid.astype(np.float64), frames

    def handover(valid, rate, ramp_s=None):
        valid = np.asarray(valid, dtype=bool)
        return valid.astype(np.float64), valid.copy()

    hook = "engagement" if hasattr(dropouts, "engagement") else "handover"
    with mock.patch.object(dropouts, hook, {"engagement": engagement, "handover": handover}[hook]):
        yield


def gap_in_the_speech(recording, rest: tuple[float, float], seconds: float) -> tuple[float, float, bool]:
    """(start, end, moved): a ``seconds`` gap centred in the speech (first to last production), moved the
    least that keeps it ``MARGIN_S`` clear of the rest interval (``moved`` says whether it had to)."""
    from tonguevis.workflows import find_recording_productions

    table = find_recording_productions(recording, keep=None)
    if len(table):
        first, last = min(p.start for p in table), max(p.end for p in table)
    else:
        first, last = float(recording.times[0]), float(recording.times[-1])
    start = 0.5 * (first + last) - 0.5 * seconds
    lo, hi = rest[0] - MARGIN_S, rest[1] + MARGIN_S
    moved = start < hi and start + seconds > lo
    if moved:  # overlaps the rest: move before or after it, whichever is nearer
        before, after = lo - seconds, hi
        start = before if abs(before - start) <= abs(after - start) else after
    return float(start), float(start + seconds), bool(moved)


def with_gap(recording, sensor: str, start: float, end: float):
    """A copy with ``sensor`` NaN in [start, end)."""
    lost = (recording.times >= start) & (recording.times < end)
    x = recording.sensors[sensor].copy()
    x[lost] = np.nan
    return recording.with_sensors({**recording.sensors, sensor: x})


def _jump(motion, window: tuple[float, float]) -> float:
    """max over the frames in ``window`` (s) and over nodes of |u(t+1) - 2u(t) + u(t-1)|, metres."""
    frames = np.flatnonzero((motion.times >= window[0]) & (motion.times <= window[1]))
    u = motion.displacements(slice(max(0, frames[0] - 1), frames[-1] + 2))
    return float(np.linalg.norm(u[2:] - 2 * u[1:-1] + u[:-2], axis=2).max())


def figures(motion, gap: tuple[float, float]) -> dict:
    """Summary figures of one run; the jumps around ``gap`` (s)."""
    meta = motion.metadata
    p = meta["plausibility"]
    flagged = sorted(set(meta.get("recovered_frames", [])) | set(meta.get("implausible_frames", [])))
    return {
        "volume_change_max_percent": float(p["volume_change_max_percent"]),
        "energy_peak_mJ": float(1e3 * np.max(motion.energy)),
        "largest_node_mm": float(p["largest_node_displacement_mm"]),
        "flagged_frames": len(flagged),
        "flagged_at_s": [round(float(motion.times[k]), 2) for k in flagged[:3]],
        "flagged_frames_after_loss": [int(k - np.searchsorted(motion.times, gap[0])) for k in flagged[:3]],
        "jump_max_mm": 1e3 * _jump(motion, (gap[0] - MARGIN_S, gap[1] + MARGIN_S)),
        "jump_at_return_mm": 1e3 * _jump(motion, (gap[1] - MARGIN_S, gap[1] + MARGIN_S)),
    }


def measure(path, sensors=SENSORS, seconds: float = 1.0, model=None, modes: int = 100,
            sensor_patches: str | float | None = None, tongue_size="adult") -> dict:
    """All runs of one recording: {"rest", "gap", "runs": {(sensor or None, "new"|"old"): figures or {"refused": msg}}}.

    ``sensor_patches`` None (default): the dynamics' own dropout handling, as docs/dropouts.md measured it
    (the patches, the app's default, act after the dynamics and are measured apart).  ``tongue_size`` as
    :class:`~tonguevis.sim.settings.RunSettings` (default: the adult size, every front end's)."""
    from tonguevis.errors import TonguevisError
    from tonguevis.sim import TongueModel
    from tonguevis.workflows import open_recording, simulate_recording

    model = model or TongueModel.default()
    recording = open_recording(path)
    full = simulate_recording(recording, model, modes=modes, sensor_patches=sensor_patches, tongue_size=tongue_size)
    rest = tuple(float(t) for t in full.metadata["rest"]["interval"])
    *gap, moved = gap_in_the_speech(recording, rest, seconds)
    runs = {(None, "new"): figures(full, gap)}
    for sensor in sensors:
        lost = with_gap(recording, sensor, *gap)
        for behaviour in ("new", "old"):
            patch = released_at_once() if behaviour == "old" else contextlib.nullcontext()
            try:
                with patch:
                    motion = simulate_recording(lost, model, modes=modes, rest=rest, sensor_patches=sensor_patches,
                                                tongue_size=tongue_size)
            except TonguevisError as exc:
                runs[(sensor, behaviour)] = {"refused": str(exc)}
                continue
            runs[(sensor, behaviour)] = figures(motion, gap)
            runs[(sensor, behaviour)]["released_frames"] = int(motion.metadata["dropouts"]["released_frames"])
    return {"rest": rest, "rest_how": full.metadata["rest"]["how"], "gap": tuple(gap), "gap_moved": moved,
            "rate": float(recording.rate),
            "runs": runs}


def code_version() -> str:
    """The commit the figures were measured at, and whether tonguevis/ had uncommitted changes."""
    import subprocess

    try:
        sha = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "--", "tonguevis"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown (not a git checkout)"
    return f"commit {sha}" + (" with uncommitted changes to tonguevis/" if dirty else "")


def markdown(results: dict, seconds: float, modes: int, elapsed: float) -> str:
    lines = [
        "# Sensor dropouts on real recordings",
        "",
        f"*Generated by `scripts/report_dropouts.py`; do not edit by hand. Code: {code_version()}. "
        f"Shipped tongue, {modes} modes, default "
        f"settings (sensor stiffness 20, modal warping, the tongue at the adult size, no sensor patches); {elapsed:.0f} s. Needs ../shared/data (the recordings are "
        "not in this repository).*",
        "",
        f"One tongue sensor is set to NaN for {seconds:g} s in the middle of the speech (first to last production, "
        f"moved clear of the rest window when they overlap), as a bad-status stretch of an NDI Wave export gives, "
        "and the recording is simulated again with the rest interval of the run without the dropout. "
        "**handover** is what tonguevis does at the code version above (`tonguevis.sim.dropouts`, whose docstring "
        "says how): the lost sensor handed over to the model over 0.1 s, and back over 0.1 s when it returns. "
        "**at once** is the behaviour before: the sensor released in the first frame it is missing. "
        "Jump: the worst frame-to-frame change of the shape, max over nodes of |u(t+1) − 2u(t) + u(t−1)|, "
        f"from {MARGIN_S:g} s before the gap to {MARGIN_S:g} s after it (the same frames in the run without the "
        "dropout). Flagged: frames that ran away and kept the previous shape, or that no tongue could produce. "
        "In brackets: the ratio to the run without the dropout.",
        "",
    ]
    for name, r in results.items():
        moved = " (the middle of the speech overlaps the rest: moved clear of it)" if r["gap_moved"] else ""
        lines.append(f"- {name}: rest {r['rest'][0]:.2f}-{r['rest'][1]:.2f} s ({r['rest_how']}), "
                     f"gap {r['gap'][0]:.2f}-{r['gap'][1]:.2f} s{moved}")
    lines += [
        "",
        "| recording | lost sensor | dropout | max volume change (%) | peak energy (mJ) | largest node (mm) "
        "| flagged frames | jump (mm) | of which at the return (mm) |",
        "| --- | --- | --- | ---: | ---: | ---: | --- | ---: | ---: |",
    ]
    for name, r in results.items():
        none = r["runs"][(None, "new")]
        for (sensor, behaviour), f in r["runs"].items():
            what = "none" if sensor is None else {"new": "handover", "old": "at once"}[behaviour]
            if "refused" in f:
                lines.append(f"| {name} | {sensor or '-'} | {what} | refused: {f['refused']} | | | | | |")
                continue
            ratio = lambda key: "" if sensor is None else f" ({f[key] / none[key]:.2f}x)"  # noqa: E731
            flagged = str(f["flagged_frames"]) + (f" (at {', '.join(map(str, f['flagged_at_s']))} s"
                                                  f"{', ...' if f['flagged_frames'] > 3 else ''})"
                                                  if f["flagged_frames"] else "")
            lines.append(f"| {name} | {sensor or '-'} | {what} | "
                         f"{f['volume_change_max_percent']:.2f}{ratio('volume_change_max_percent')} | "
                         f"{f['energy_peak_mJ']:.3f}{ratio('energy_peak_mJ')} | "
                         f"{f['largest_node_mm']:.1f} | {flagged} | {f['jump_max_mm']:.2f}{ratio('jump_max_mm')} | "
                         f"{f['jump_at_return_mm']:.2f}{ratio('jump_at_return_mm')} |")
    lines += ["", "## What the figures show", ""] + findings(results)
    return "\n".join(lines) + "\n"


def findings(results: dict) -> list[str]:
    """Sentences read off the figures (so they stay true when the figures change)."""
    out = []
    for name, r in results.items():
        none = r["runs"][(None, "new")]
        for (sensor, behaviour), f in r["runs"].items():
            if sensor is None or "refused" in f:
                continue
            what = {"new": "with the handover", "old": "released at once"}[behaviour]
            late = f["flagged_frames_after_loss"]
            if late:
                release = {"new": (round(RAMP_S * r["rate"]), " (the release, at the end of the ramp)"),
                           "old": (0, " (the release)")}[behaviour]
                out.append(f"- {name}, {sensor} {what}: {f['flagged_frames']} frame(s) flagged, "
                           f"{', '.join(map(str, late))} frame(s) after the first missing one"
                           + (release[1] if late[0] == release[0] else "") + ".")
            for key, label in (("energy_peak_mJ", "peak energy"), ("volume_change_max_percent", "volume change")):
                if f[key] > 1.5 * none[key]:
                    out.append(f"- {name}, {sensor} {what}: {label} {f[key] / none[key]:.2f}x the run without "
                               "the dropout.")
        for sensor in dict.fromkeys(s for s, _ in r["runs"] if s is not None):
            new, old = r["runs"].get((sensor, "new"), {}), r["runs"].get((sensor, "old"), {})
            if "jump_at_return_mm" in new and "jump_at_return_mm" in old and \
                    abs(new["jump_at_return_mm"] - old["jump_at_return_mm"]) <= 0.01 * old["jump_at_return_mm"]:
                out.append(f"- {name}, {sensor}: the shape jumps as much when the sensor comes back with the "
                           f"handover as at once ({new['jump_at_return_mm']:.2f} mm, "
                           f"{new['jump_at_return_mm'] / none['jump_at_return_mm']:.1f}x the run without the "
                           "dropout): the ramp back onto the measurement does not act.")
    return out or ["- Nothing beyond the run without the dropout: no flagged frame, no figure over 1.5x."]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="length of the dropout (default 1 s)")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--md", type=Path, default=REPO / "docs" / "dropouts.md")
    args = parser.parse_args(argv)
    from tonguevis._files import atomic_write_text
    from tonguevis.sim import TongueModel

    missing = [SHARED.joinpath(*p) for p in RECORDINGS.values() if not SHARED.joinpath(*p).exists()]
    if missing:
        print(f"needs the real recordings in ../shared/data; missing: {', '.join(map(str, missing))}", file=sys.stderr)
        return 2
    model = TongueModel.default()
    t0 = time.perf_counter()
    results = {name: measure(SHARED.joinpath(*parts), seconds=args.seconds, model=model, modes=args.modes)
               for name, parts in RECORDINGS.items()}
    text = markdown(results, args.seconds, args.modes, time.perf_counter() - t0)
    atomic_write_text(args.md, text)
    print(text)
    print(f"wrote {args.md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
