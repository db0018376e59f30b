"""How believable a motion is: far-field amplification, volume change, sensor misfit.

A tongue driven by sensors that move a few millimetres should not move any of
its nodes much further than the sensors did, nor change its volume (tongue
tissue is nearly incompressible), and its sensor nodes should stay near the
sensors.  Every simulation reports these figures (``motion.metadata["plausibility"]``),
the CLI prints :func:`plausibility_line` and the app shows it in its status bar.
"""

from __future__ import annotations

import numpy as np

#: Per frame, beyond these a frame is absurd (no tongue does it).
ABSURD_VOLUME = 0.10  # tongue tissue is nearly incompressible: the paper's Fig. 5 stays under ~1 %
ABSURD_AMPLIFICATION = 10.0
MOVED_M = 1e-3  # per-frame amplification only where some sensor moved this far from rest


def plausibility_figures(displacements, sensor_displacement, volume_change, residual):
    """Summary figures of a motion and the frames no tongue could produce.

    displacements : (F, n, 3) displacements of the nodes counted (a simulation counts the
        surface's: :func:`tonguevis.sim.figures.frame_figures`); sensor_displacement : (F, S, 3)
    measured sensor displacements (NaN = missing); volume_change (F,);
    residual (F, S) sensor misfit, metres.  The whole array is the plain
    reference; a long motion gives :func:`plausibility_from_largest` the
    largest node displacement per frame, computed chunk by chunk
    (:func:`tonguevis.sim.figures.frame_figures`).
    """
    node = np.linalg.norm(displacements, axis=2).max(axis=1) if len(displacements) else np.zeros(0)
    return plausibility_from_largest(node, sensor_displacement, volume_change, residual)


def plausibility_from_largest(node, sensor_displacement, volume_change, residual):
    """:func:`plausibility_figures` from ``node`` (F,), the largest node displacement of each frame in metres."""
    node = np.asarray(node, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        sensor = np.nanmax(np.linalg.norm(sensor_displacement, axis=2), axis=1, initial=0.0)
    sensor = np.where(np.isfinite(sensor), sensor, 0.0)
    moved = sensor >= MOVED_M
    per_frame = np.where(moved, node / np.where(moved, sensor, 1.0), np.nan)
    overall = float(node.max() / sensor.max()) if len(node) and sensor.max() > 0 else float("nan")
    absurd = np.flatnonzero((np.abs(volume_change) > ABSURD_VOLUME) | (per_frame > ABSURD_AMPLIFICATION)
                            | ~np.isfinite(volume_change))
    res = residual[np.isfinite(residual)]
    figures = {
        "amplification": overall,
        "amplification_frame_max": float(np.nanmax(per_frame)) if moved.any() else float("nan"),
        "largest_node_displacement_mm": float(1e3 * node.max()) if len(node) else 0.0,
        "largest_sensor_displacement_mm": float(1e3 * sensor.max()) if len(sensor) else 0.0,
        "volume_change_max_percent": float(100 * np.abs(volume_change).max()) if len(volume_change) else 0.0,
        "sensor_misfit_max_mm": float(1e3 * res.max()) if len(res) else 0.0,
        "sensor_misfit_rms_mm": float(1e3 * np.sqrt(np.mean(res ** 2))) if len(res) else 0.0,
    }
    return figures, absurd


def plausibility_line(metadata: dict, short: bool = False) -> str:
    """One line for users: amplification, volume change, sensor misfit, flagged frames; ``short``:
    the same figures in fewer words, for the app's one status line (a 1920-pixel window cut the
    long one in the middle of the figures)."""
    p = metadata.get("plausibility")
    if not p:
        return "plausibility: not recorded in this motion"
    flagged = len(metadata.get("recovered_frames", [])) + len(metadata.get("implausible_frames", []))
    node, sensor = p["largest_node_displacement_mm"], p["largest_sensor_displacement_mm"]
    if short:
        text = (f"far-field amplification {p['amplification']:.2f} ({node:.1f} / {sensor:.1f} mm), volume change ≤ "
                f"{p['volume_change_max_percent']:.2f} %, sensor misfit {p['sensor_misfit_rms_mm']:.2f} mm RMS, "
                f"max {p['sensor_misfit_max_mm']:.2f} mm")
    else:
        text = (f"far-field amplification {p['amplification']:.2f} (largest surface node {node:.1f} mm / largest "
                f"sensor {sensor:.1f} mm), max volume change {p['volume_change_max_percent']:.2f} %, sensor misfit "
                f"{p['sensor_misfit_rms_mm']:.2f} mm RMS (max {p['sensor_misfit_max_mm']:.2f} mm)")
    return text + (f"; {flagged} frames flagged" if flagged else "")


def plausibility_status(metadata: dict) -> str:
    """:func:`plausibility_line` in fewer words, for the app's status line."""
    return plausibility_line(metadata, short=True)


def contact_line(metadata: dict) -> str:
    """One line for users on the palate contact of a motion simulated against a palate ("" without).

    What the geometry says: the deepest point inside the palate (a sensor above it counts: the
    tongue follows the sensor there), the frames in which the tongue touches or enters it, the
    largest contact area, each sensor measured above the palate, and a registration raise."""
    c = metadata.get("contact")
    if not c:
        return ""
    text = (f"palate: deepest penetration {c['penetration_max_mm']:.2f} mm, {c['frames_in_contact']} frames in contact, "
            f"largest contact area {c['contact_area_max_mm2']:.0f} mm²")
    above = c.get("sensors_above_palate")
    if above is None:  # a motion saved before the sensors were counted: the solver's conflicts
        names = metadata.get("sensor_names") or []
        above = {names[int(k)] if int(k) < len(names) else f"sensor {k}": {"frames": n, "deepest_mm": float("nan")}
                 for k, n in c.get("conflicts", {}).get("by_sensor_index", {}).items()}
    if above:
        text += "; above the palate (the tongue follows them there): " + ", ".join(
            f"{name} in {v['frames']} frames" + (f" (up to {v['deepest_mm']:.1f} mm)" if v["deepest_mm"] == v["deepest_mm"]
                                                 else "") for name, v in above.items())
    if c.get("largest_contact_where"):
        text += f" ({c['largest_contact_where']})"
    closures = c.get("closures")
    if closures:
        where = c.get("closures_where")
        touching = c.get("closures_touching", 0)
        part = "the tip" if closures.get("articulator", "TT") == "TT" else "the dorsum"
        text += (f"; {part} touches at {touching} of {closures['closures']} stop closures"
                 + (f" ({where}), pressed on the palate there" if touching else
                    ": pulled towards the palate there, short of it"))
    if c.get("closures_dropped"):
        text += f"; the closures not pressed ({c['closures_dropped']}): the sensors and the contact alone"
    registered = (c.get("palate") or {}).get("head_registration")
    if registered:
        text += (f"; palate registered into the speech's head frame by {', '.join(registered['references'])} "
                 f"(moved {registered['moved_mm']:.1f} mm, residual {registered['residual_mm']:.2f} mm)")
    text += speaker_palate_words((c.get("palate") or {}).get("speaker_palate"))
    return text


def speaker_palate_words(info: dict | None) -> str:
    """"; the speaker's palate: ..." (what was traced, how far the speech moved it, the velum), or ""."""
    if not info:
        return ""
    text = f"; the speaker's palate: {100 * info['traced_share']:.0f} % of the roof as traced"
    if info.get("traced_raised_mm", 0.0) > 0.05:
        x, _ = info["traced_raised_at_mm"]
        text += (f", raised up to {info['traced_raised_mm']:.1f} mm (at x {x:.0f} mm; "
                 f"{100 * info['traced_raised_share']:.0f} % of it over 0.5 mm) where the sensors went above it")
    if info.get("estimated_raised_mm", 0.0) > 0.05:
        text += f", the rest estimated from the speech (raised up to {info['estimated_raised_mm']:.1f} mm)"
    if info.get("velum_lifted_frames"):
        text += (f", the velum lifting up to {info['velum_lift_max_mm']:.1f} mm with the dorsum "
                 f"({info['velum_lifted_frames']} frames)")
    return text
