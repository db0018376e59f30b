"""Markdown tables of validation results (for ``tonguevis validate --md`` and scripts/validate_all.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable

import numpy as np

METHOD_LABELS = {
    "model": "model (warped)",
    "linear": "linear modal",
    "static": "quasi-static (warped)",
    "kinematic": "kinematic RBF",
}


def fmt(value: Any, digits: int = 2) -> str:
    """A number for a table; '–' for missing."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "–"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    return f"{float(value):.{digits}f}"


def methods_of(doc: dict[str, Any]) -> list[str]:
    return [m for m in ("model", "linear", "static", "kinematic") if m in doc["settings"].get("methods", [])]


def sensor_table(doc: dict[str, Any]) -> str:
    """One row per held-out sensor: RMSE (mm) and mean correlation of every method; best RMSE in bold."""
    methods = methods_of(doc)
    head = ["held out", "node", "peak mm"] + [f"{METHOD_LABELS[m]} RMSE mm / r" for m in methods]
    rows = [head, ["---"] * len(head)]
    for name, s in doc["sensors"].items():
        rmses = [s.get(f"{m}_rmse_mm") for m in methods]
        finite = [r for r in rmses if r is not None]
        best = min(finite) if finite else None
        cells = [name, fmt(s.get("node")), fmt(s.get("measured_peak_mm"), 1)]
        for m, r in zip(methods, rmses):
            text = f"{fmt(r)} / {fmt(s.get(f'{m}_corr'))}"
            cells.append(f"**{text}**" if r is not None and r == best else text)
        rows.append(cells)
    return "\n".join("| " + " | ".join(r) + " |" for r in rows)


def axis_table(doc: dict[str, Any]) -> str:
    """Per-axis RMSE (mm) and Pearson r (x anterior, y left, z up) of every method and sensor."""
    methods = methods_of(doc)
    rows = [["held out", "method", "RMSE x", "RMSE y", "RMSE z", "r x", "r y", "r z"], ["---"] * 8]
    for name, s in doc["sensors"].items():
        for m in methods:
            rm = s.get(f"{m}_rmse_axes_mm") or [None] * 3
            rc = s.get(f"{m}_corr_axes") or [None] * 3
            rows.append([name, METHOD_LABELS[m]] + [fmt(v) for v in rm] + [fmt(v) for v in rc])
    return "\n".join("| " + " | ".join(r) + " |" for r in rows)


def summary_lines(doc: dict[str, Any]) -> list[str]:
    """Bullet lines of the recording's full-simulation figures."""
    r = doc["recording"]
    lines = [
        f"- file: `{Path(r['file']).name}`, {fmt(r['duration_s'], 1)} s at {fmt(r['rate_hz'], 0)} Hz; tongue sensors "
        f"{', '.join(r['tongue_sensors'])} on nodes {', '.join(f'{k}={v}' for k, v in r['sensor_nodes'].items())}",
        f"- rest interval {fmt(r['rest_interval_s'][0])}-{fmt(r['rest_interval_s'][1])} s ({r['rest_interval_from']}); "
        f"alignment scale {fmt(r['alignment_scale'], 3)}, rest sensors to their nodes {fmt(r['alignment_rms_mm'])} mm RMS "
        f"({'midsagittal' if r['midsagittal_alignment'] else '3-D'} fit)",
        f"- full simulation (all sensors, warped): volume change max {fmt(r['volume_change_max_pct'])} %, "
        f"mean {fmt(r['volume_change_mean_pct'])} %; sensor residual max {fmt(r['sensor_residual_max_mm'], 4)} mm, "
        f"mean {fmt(r['sensor_residual_mean_mm'], 4)} mm; unconverged frames {r['unconverged_frames']}",
    ]
    if r.get("drift_mm") is None:
        lines.append("- drift: not measured (the sensors never return within 0.5 mm of rest after moving)")
    else:
        lines.append(f"- drift after the return to rest (t = {fmt(r['drift_time_s'])} s, sensors within "
                     f"{fmt(r['drift_sensor_offset_mm'])} mm of rest): mesh at most {fmt(r['drift_mm'])} mm from rest, "
                     f"{fmt(r.get('drift_beyond_static_mm'), 3)} mm from the quasi-static shape for the same targets")
    return lines


def recording_markdown(doc: dict[str, Any], title: str | None = None) -> str:
    """The report of one validation document (``ValidationResult.as_dict()``)."""
    s = doc["settings"]
    parts = [f"## {title or Path(doc['recording']['file']).name} ({s['landmarks']} landmarks, {s['modes']} modes)", ""]
    parts += summary_lines(doc)
    parts += ["", "RMSE in mm (model frame) / mean per-axis correlation; best RMSE in bold.", "", sensor_table(doc), ""]
    return "\n".join(parts)


def wins(docs: Iterable[dict[str, Any]], method: str, against: str) -> tuple[int, int]:
    """(held-out sensors where ``method`` has the lower RMSE than ``against``, sensors compared)."""
    better = total = 0
    for doc in docs:
        for s in doc["sensors"].values():
            a, b = s.get(f"{method}_rmse_mm"), s.get(f"{against}_rmse_mm")
            if a is None or b is None:
                continue
            total += 1
            better += a < b
    return better, total
