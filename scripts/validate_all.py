#!/usr/bin/env python
"""Leave-one-sensor-out validation on the real recordings and the demo corpus -> docs/validation.md.

Runs :func:`tonguevis.analysis.validate` with both landmark modes ("speaker"
and "rule") on
* the real recordings in ../shared/data/ema that have >= 3 tongue sensors
  and enough frames (the Haskins MVIEW file: TT, TB, TBK; skipped with a
  note when ../shared is absent), and
* the synthetic demo corpus data/spk*_*.tsv (all 12 files, or --demo-files),
then a sensitivity check (modes, Poisson's ratio) on one real and one demo
recording, and writes the Markdown report.  docs/validation.md is written by
this script only; never edit it by hand.  ``--json-dir`` keeps the per-run
JSON documents (never commit those of third-party recordings).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
REAL = [("ema/mview/F01_B01_S01_R01_N.mat", "haskins")]
SKIPPED_REAL = [
    ("ema/carstens/rticulate_0025.pos", "3 tongue channels but only 20 frames (0.1 s): no motion to predict"),
    ("ema/ndi_wave/Example3.tsv", "1 s of an NDI Wave export with no sensor map saying which channel is the tongue"),
    ("ema/carstens/artk_ag50*.pos, ema/est_track/*", "format test files with synthetic values (1, 2, 3 ...)"),
]
METHODS = ("model", "linear", "static", "kinematic")
LABEL = {"model": "model (warped)", "linear": "linear modal", "static": "quasi-static", "kinematic": "kinematic RBF"}


def load_model(args):
    from tonguevis.sim import TongueModel

    if args.mesh is None:
        return TongueModel.default()
    options = {"axes": args.axes} if args.axes else {}
    return TongueModel.from_mesh(args.mesh, **options)


def with_poisson(model, poisson: float):
    """The same mesh and landmarks with another Poisson's ratio (never re-read: the files could change mid-run)."""
    from dataclasses import replace

    from tonguevis.sim import TongueModel

    return TongueModel(model.mesh, model.landmarks, replace(model.material, poisson=poisson))


SENSITIVITY = (("100 modes, ν = 0.49", 100, None), ("40 modes", 40, None), ("200 modes", 200, None),
               ("100 modes, ν = 0.45", 100, 0.45))


def tag_of(label: str) -> str:
    return label.replace(" ", "").replace(",", "-")


def run_one(path: Path, sensor_map, model, modes: int, landmarks: str, json_dir: Path | None, tag: str):
    from tonguevis.analysis import validate
    from tonguevis.workflows import open_recording

    rec = open_recording(path, sensor_map)
    t0 = time.perf_counter()
    result = validate(rec, model, modes=modes, landmarks=landmarks)
    doc = result.as_dict()
    doc["recording"]["file"] = path.name  # no local paths in the report
    doc["elapsed_s"] = time.perf_counter() - t0
    doc["run"] = {"recording": path.stem, "tag": tag, "data": "demo" if path.parent == REPO / "data" else "real"}
    if json_dir is not None:
        json_dir.mkdir(parents=True, exist_ok=True)
        (json_dir / f"{path.stem}-{landmarks}-{tag}.json").write_text(json.dumps(doc, indent=1))
    print(f"  {path.name} [{landmarks}, {tag}]: {doc['elapsed_s']:.1f} s; " + ", ".join(
        f"{n} {s['model_rmse_mm']:.2f}/{s['kinematic_rmse_mm']:.2f} mm" for n, s in doc["sensors"].items()),
        file=sys.stderr)
    return doc


# --------------------------------------------------------------------------- tables
def fmt(v, d=2):
    return "–" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:.{d}f}"


def table(rows):
    return "\n".join("| " + " | ".join(map(str, r)) + " |" for r in [rows[0], ["---"] * len(rows[0])] + rows[1:])


def sensor_rows(docs, label_file=True):
    rows = [(["recording"] if label_file else []) + ["held out", "drivers", "peak mm"]
            + [f"{LABEL[m]} RMSE / r" for m in METHODS]]
    for doc in docs:
        for name, s in doc["sensors"].items():
            rmses = {m: s.get(f"{m}_rmse_mm") for m in METHODS}
            best = min(v for v in rmses.values() if v is not None)
            cells = [f"{fmt(rmses[m])} / {fmt(s.get(f'{m}_corr'))}" for m in METHODS]
            cells = [f"**{c}**" if rmses[m] == best else c for m, c in zip(METHODS, cells)]
            rows.append(([Path(doc["recording"]["file"]).stem] if label_file else [])
                        + [name, " ".join(s["drivers"]), fmt(s["measured_peak_mm"], 1)] + cells)
    return table(rows)


def recording_rows(docs):
    rows = [["recording", "landmarks", "rest (s, how)", "align RMS mm", "scale", "vol. max %", "vol. mean %",
             "residual max mm", "unconverged", "drift mm (sensors off rest mm; beyond static mm)"]]
    for doc in docs:
        r = doc["recording"]
        drift = ("–" if r["drift_mm"] is None else
                 f"{fmt(r['drift_mm'])} ({fmt(r['drift_sensor_offset_mm'])}; {fmt(r['drift_beyond_static_mm'], 3)})")
        rows.append([Path(r["file"]).stem, doc["settings"]["landmarks"],
                     f"{fmt(r['rest_interval_s'][0])}-{fmt(r['rest_interval_s'][1])} ({r['rest_interval_from']})",
                     fmt(r["alignment_rms_mm"]), fmt(r["alignment_scale"], 3), fmt(r["volume_change_max_pct"]),
                     fmt(r["volume_change_mean_pct"]), f"{r['sensor_residual_max_mm']:.1e}",
                     r["unconverged_frames"], drift])
    return table(rows)


def scores(docs, method, key="rmse_mm"):
    return np.array([s[f"{method}_{key}"] for d in docs for s in d["sensors"].values()
                     if s.get(f"{method}_{key}") is not None])


def overview_rows(groups):
    rows = [["data", "landmarks", "held-out runs"] + [f"{LABEL[m]} RMSE mm (r)" for m in METHODS]
            + ["model beats kinematic", "model beats linear"]]
    for (data, landmarks), docs in groups.items():
        if not docs:
            continue
        cells = [f"{fmt(scores(docs, m).mean())} ({fmt(scores(docs, m, 'corr').mean())})" for m in METHODS]
        a, b = scores(docs, "model"), scores(docs, "kinematic")
        c = scores(docs, "linear")
        rows.append([data, landmarks, len(a)] + cells + [f"{int(np.sum(a < b))} of {len(a)}",
                                                          f"{int(np.sum(a < c))} of {len(a)}"])
    return table(rows)


def axis_rows(groups):
    """Mean per-axis RMSE and r of each method per data group."""
    rows = [["data", "landmarks", "method", "RMSE x", "RMSE y", "RMSE z", "r x", "r y", "r z"]]
    for (data, landmarks), docs in groups.items():
        if not docs:
            continue
        for m in METHODS:
            rm = np.array([s[f"{m}_rmse_axes_mm"] for d in docs for s in d["sensors"].values()], dtype=float)
            rc = np.array([s[f"{m}_corr_axes"] for d in docs for s in d["sensors"].values()], dtype=float)
            rows.append([data, landmarks, LABEL[m]] + [fmt(v) for v in np.nanmean(rm, axis=0)]
                        + [fmt(v) for v in np.nanmean(rc, axis=0)])
    return table(rows)


# --------------------------------------------------------------------------- conclusions
def _runs(docs):
    """(recording stem, sensor, scores) of every held-out run."""
    return [(Path(d["recording"]["file"]).stem, n, s) for d in docs for n, s in d["sensors"].items()]


def conclusions(groups, sensitivity) -> list[str]:
    """Plain statements computed from the tables (no hand-typed figures)."""
    out = []
    for (data, landmarks), docs in groups.items():
        if not docs:
            continue
        runs = _runs(docs)
        model, lin, sta, kin = (scores(docs, m) for m in METHODS)
        losses = [(f, n, s) for f, n, s in runs if s["model_rmse_mm"] > s["kinematic_rmse_mm"]]
        inside = [(f, n, s) for f, n, s in runs if not s["outside_drivers"]]
        outside = [(f, n, s) for f, n, s in runs if s["outside_drivers"]]
        lost_in = sum(not s["outside_drivers"] for _, _, s in losses)
        line = (f"- **{data}, {landmarks} landmarks**: mean held-out RMSE {fmt(model.mean())} mm for the warped "
                f"model against {fmt(kin.mean())} mm for the kinematic interpolation; the model loses to it in "
                f"{len(losses)} of {len(runs)} runs")
        if losses:
            names = sorted({n for _, n, _ in losses})
            line += (f" (held out: {', '.join(names)}; {lost_in} of these {len(losses)} runs predict a sensor inside "
                     "the drivers' hull, where interpolation is at its best)")
        out.append(line + ".")
        for part, label in ((inside, "inside the drivers' hull"), (outside, "outside it (extrapolation)")):
            if part:
                mm = np.mean([s["model_rmse_mm"] for *_, s in part])
                km = np.mean([s["kinematic_rmse_mm"] for *_, s in part])
                out.append(f"  Held-out sensors {label}: model {fmt(mm)} mm, kinematic {fmt(km)} mm ({len(part)} run{'s' if len(part) > 1 else ''}).")
        d_lin = model - lin
        verdict = ("modal warping changes the held-out prediction very little at these amplitudes."
                   if np.abs(d_lin).max() < 0.2 else
                   "no difference on average, though single runs differ by up to that much."
                   if abs(d_lin.mean()) < 0.05 else
                   "warping helps on average." if d_lin.mean() < 0 else "warping does worse on average.")
        out.append(f"  Warped vs linear modal: mean difference {fmt(d_lin.mean(), 3)} mm (largest "
                   f"{fmt(np.abs(d_lin).max(), 3)} mm); " + verdict)
        d_sta = model - sta
        out.append(f"  Quasi-static vs dynamic: mean |difference| {fmt(np.abs(d_sta).mean(), 3)} mm, largest "
                   f"{fmt(np.abs(d_sta).max(), 3)} mm: "
                   + ("a static solve of the same model does as well as the dynamic one (with this damping the "
                      "model's own dynamics add nothing the sensors did not already impose)."
                      if np.abs(d_sta).max() < 0.1 else "the dynamics change the prediction for some sensors."))
        blind = []
        for f, n, s in runs:
            moved = [a for a, sd in zip("xyz", s["measured_std_axes_mm"]) if sd is not None and sd >= 1.0]
            for a in moved:
                i = "xyz".index(a)
                best = max(s[f"{m}_corr_axes"][i] for m in METHODS if s[f"{m}_corr_axes"][i] is not None)
                if best < 0.5:
                    blind.append(f"{n} {a} in {f} (best r {fmt(best)})")
        if blind:
            out.append("  Motion that no predictor follows (r < 0.5 along an axis where the sensor moved >= 1 mm): "
                       + "; ".join(blind) + ". Neither the physical nor the kinematic predictors recover it from "
                       "the other sensors: it is not in them (the tip, say, raised on its own), so this is a limit "
                       "of what a held-out test with this layout can show, not the fault of one model.")
    for data in ("real", "demo"):
        sp, ru = groups.get((data, "speaker"), []), groups.get((data, "rule"), [])
        if sp and ru:
            a, b = scores(sp, "model").mean(), scores(ru, "model").mean()
            align_sp = np.mean([d["recording"]["alignment_rms_mm"] for d in sp])
            out.append(f"- Landmarks on the {data} data: speaker layout {fmt(a)} mm, placement rule {fmt(b)} mm mean "
                       f"RMSE; the rest sensors sit {fmt(align_sp)} mm RMS from the rule nodes after the similarity "
                       "fit. " + ("Snapping to the speaker's own layout helps." if a < b - 0.05 else
                                  "The rule nodes do as well here." if abs(a - b) <= 0.05 else
                                  "The rule nodes do better here."))
    for name, rows in sensitivity.items():
        if rows:
            values = dict(rows)
            labels = [label for label, _ in rows]
            base = values[labels[0]]
            line = (f"- Sensitivity on {name} (speaker landmarks, mean held-out RMSE of the warped model): "
                    + "; ".join(f"{label}: {fmt(v)} mm" for label, v in rows) + ". ")
            few, many, soft = values[labels[1]], values[labels[2]], values[labels[3]]
            if many < base - 0.1 * base:
                line += (f"More modes help ({fmt(base)} → {fmt(many)} mm): {labels[0].split(',')[0]} are too few "
                         "to bend the surface between sensors as sharply as the data. ")
            elif few > base + 0.1 * base:
                line += f"Fewer modes hurt ({fmt(few)} mm), more add little ({fmt(many)} mm). "
            else:
                line += "The number of modes changes little. "
            if soft < base - 0.05 * base:
                line += (f"A lower Poisson's ratio helps ({fmt(soft)} mm): volumetric locking of linear tets at "
                         "ν = 0.49 stiffens the model.")
            else:
                line += (f"ν = 0.45 gives {fmt(soft)} mm: volumetric locking of the linear tets at ν = 0.49 does "
                         "not explain the errors.")
            out.append(line)
    return out


def from_json(folder: Path):
    """(groups, sensitivity, elapsed) from the documents of an earlier ``--json-dir`` run."""
    real_stems = {Path(rel).stem for rel, _ in REAL}
    groups: dict[tuple[str, str], list] = {}
    by_tag: dict[str, dict[str, dict]] = {}
    elapsed = 0.0
    for path in sorted(folder.glob("*.json")):
        doc = json.loads(path.read_text())
        stem = Path(doc["recording"]["file"]).stem
        tag = path.stem[len(stem) + 1:].split("-", 1)[1]
        elapsed += doc.get("elapsed_s", 0.0)
        if tag == "main":
            data = "real" if stem in real_stems else "demo"
            groups.setdefault((data, doc["settings"]["landmarks"]), []).append(doc)
        else:
            by_tag.setdefault(stem, {})[tag] = doc
    order = {("real", "speaker"): 0, ("demo", "speaker"): 1, ("real", "rule"): 2, ("demo", "rule"): 3}
    groups = dict(sorted(groups.items(), key=lambda kv: order[kv[0]]))
    stems = sorted(by_tag, key=lambda s: (s not in real_stems, s))
    sensitivity = {stem: [(label, float(scores([by_tag[stem][tag_of(label)]], "model").mean()))
                          for label, _, _ in SENSITIVITY if tag_of(label) in by_tag[stem]] for stem in stems}
    return groups, sensitivity, elapsed


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", type=Path, help="tongue mesh (default: the shipped tongue)")
    parser.add_argument("--axes", help="axis mapping of --mesh, e.g. -x,-z,-y for ArtiSynth")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--demo-files", nargs="*", help="demo file stems (default: all spk*_*)")
    parser.add_argument("--no-sensitivity", action="store_true")
    parser.add_argument("--json-dir", type=Path, help="keep each run's JSON here (not in the repository)")
    parser.add_argument("--from-json", type=Path, metavar="DIR",
                        help="only rewrite the report from the JSON documents a --json-dir run kept")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "validation.md")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s: %(message)s")
    demo = sorted((REPO / "data").glob("spk*_*.tsv"))
    if args.demo_files:
        demo = [p for p in demo if p.stem in set(args.demo_files)]
    real = [(SHARED / rel, smap) for rel, smap in REAL if (SHARED / rel).exists()]
    groups: dict[tuple[str, str], list] = {}
    sensitivity: dict[str, list] = {}
    t0 = time.perf_counter()
    if args.from_json:
        groups, sensitivity, elapsed = from_json(args.from_json)
    else:
        model = load_model(args)
        for landmarks in ("speaker", "rule"):
            groups[("real", landmarks)] = [run_one(p, m, model, args.modes, landmarks, args.json_dir, "main")
                                           for p, m in real]
            groups[("demo", landmarks)] = [run_one(p, None, model, args.modes, landmarks, args.json_dir, "main")
                                           for p in demo]
        if not args.no_sensitivity:
            picks = [(p, m) for p, m in real[:1]] + [(p, None) for p in demo[:1]]
            for path, smap in picks:
                rows = []
                for label, modes, poisson in SENSITIVITY:
                    mdl = model if poisson is None else with_poisson(model, poisson)
                    doc = run_one(path, smap, mdl, modes, "speaker", args.json_dir, tag_of(label))
                    rows.append((label, float(scores([doc], "model").mean())))
                sensitivity[path.stem] = rows
        elapsed = time.perf_counter() - t0
    text = render(groups, sensitivity, elapsed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    from tonguevis._files import atomic_write_text

    atomic_write_text(args.out, text)
    print(f"wrote {args.out}", file=sys.stderr)
    return 0


def render(groups, sensitivity, elapsed) -> str:
    from tonguevis.analysis.validation_scores import MIN_AXIS_STD_MM

    first = next(d for docs in groups.values() for d in docs)["settings"]
    mesh, material = first["mesh"], first["material"]
    source = "the shipped tongue" if "meshes" in mesh["source"] or mesh["source"] == "default" else Path(mesh["source"]).name
    lines = [
        "# Validation: leave-one-sensor-out",
        "",
        "*Generated by `scripts/validate_all.py`; do not edit by hand. "
        f"Mesh: {mesh['nodes']} nodes, {mesh['tets']} tets ({source}); {first['modes']} modes; "
        f"E = {material['young']:g} Pa, ν = {material['poisson']:g}; validation time {elapsed / 60:.1f} min. "
        "Regenerate with `python scripts/validate_all.py` (needs ../shared/data for the real recording).*",
        "",
        "## What is measured",
        "",
        "For each tongue sensor of a recording in turn, the model is driven by all the *other* tongue sensors and "
        "the held-out sensor's node is compared with what the sensor really did. The recording is prepared once "
        "with all sensors (head and jaw correction, rest pose, similarity fit of the rest positions onto the model, "
        "sensor nodes); using every sensor's *rest* position there is fair, because rest poses are known before any "
        "motion, but the held-out sensor's *motion* never drives anything. Sensor nodes: `speaker` snaps each "
        "sensor to the dorsal-surface node nearest its aligned rest position; `rule` keeps the placement-rule nodes "
        "of the paper (§3).",
        "",
        "Predictors of the held-out displacement from rest:",
        "",
        "- **model (warped)**: the modal-warping model with Newmark dynamics, as `tonguevis simulate` runs it;",
        "- **linear modal**: the same modes without warping;",
        "- **quasi-static**: the warped model solved frame by frame without inertia or damping "
        "(Λq = Φ_sᵀR̃ᵀμ with the warped sensor constraint);",
        "- **kinematic RBF**: no mesh; SciPy's `RBFInterpolator` (linear kernel, degree-1 polynomial) of the "
        "driving sensors' displacements over their aligned rest positions, in the coordinates of the drivers' "
        "affine hull (a degree-1 polynomial in 3-D needs 4 non-coplanar centres; with 3 drivers this is planar "
        "affine interpolation, with 2 linear interpolation/extrapolation along their line; off the hull the "
        "field is constant).",
        "",
        "Scores, on the frames where every predictor and the measurement are valid, in the model frame (after "
        "the similarity fit; divide by the alignment scale for the speaker's millimetres):",
        "",
        "- **RMSE** (mm) = sqrt(mean over frames of |predicted − measured|²) of the 3-D displacement from rest; "
        "per axis likewise;",
        "- **r**: per axis (x anterior, y left, z up) the zero-lag Pearson correlation of the predicted and "
        "measured displacement trajectories, as the cross-correlation coefficients of Lucero & Munhall 1999 "
        "(Tables III-IV) and the coil-vertex correlation of Steiner et al. 2013 (§3.4); the table gives their "
        f"mean over the axes along which the sensor moved (standard deviation ≥ {MIN_AXIS_STD_MM:g} mm), so a "
        "midline sensor's lateral jitter does not count; a constant prediction scores 0.",
        "",
        "Per recording (full simulation, every tongue sensor driving, warped): volume change (% of rest volume), "
        "sensor residual, unconverged Newton frames, and drift = the largest distance of any mesh node from "
        "rest at the last frame where every sensor is back within 0.5 mm of rest after having moved 2 mm, and "
        "(beyond static) its distance from the quasi-static shape for the same sensor targets, which has no "
        "history: the part of the drift that the sensors' small offsets do not explain.",
        "",
        "Rest: the longest still interval (≥ 1 s under 10 mm/s); when there is none (the Haskins sentence is "
        "2.6 s of speech with no rest), the stillest 0.2 s window, marked `stillest window` below.",
        "",
        "## Overview",
        "",
        "Mean over held-out runs of the RMSE (mm) and, in parentheses, of r.",
        "",
        overview_rows(groups),
        "",
        "By axis (x anterior, y left, z up), mean over held-out runs:",
        "",
        axis_rows(groups),
        "",
        "## Conclusions",
        "",
        *conclusions(groups, sensitivity),
        "",
    ]
    real_docs = groups.get(("real", "speaker"), []) + groups.get(("real", "rule"), [])
    lines += ["## Real recordings", ""]
    if not real_docs:
        lines += ["../shared/data was not available: no real recording validated.", ""]
    for landmarks in ("speaker", "rule"):
        docs = groups.get(("real", landmarks), [])
        if docs:
            from tonguevis.analysis.validation_report import axis_table

            lines += [f"### {landmarks} landmarks", "", sensor_rows(docs), "", "Per axis:", ""]
            lines += [axis_table(d) for d in docs] + [""]
    lines += ["Real files not validated:", ""] + [f"- `{f}`: {why}" for f, why in SKIPPED_REAL] + [""]
    lines += ["## Demo corpus (synthetic)", "",
              "Synthetic NDI Wave recordings (data/README.md): TT, TD, TL, TR; 5 s rest, then CV trains. The four "
              "sensors form a rhombus, so each lies outside the triangle of the other three and the kinematic "
              "baseline is the parallelogram rule (e.g. TT ≈ TL + TR − TD): its error is the same rhombus defect "
              "whichever sensor is held out, hence its near-equal RMSE across the four sensors of a file.", ""]
    for landmarks in ("speaker", "rule"):
        docs = groups.get(("demo", landmarks), [])
        if docs:
            lines += [f"### {landmarks} landmarks", "", sensor_rows(docs), ""]
    lines += ["## Per recording", "", recording_rows([d for docs in groups.values() for d in docs]), ""]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
