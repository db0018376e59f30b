"""What a paper reports per production: constriction, speed, displacement, stiffness, lips, jaw, durations.

One row per production of a :class:`~tonguevis.preprocess.ProductionTable` (found, or labelled:
labels win, as everywhere), measured on its articulator (a labelled production whose label names
a place, e.g. a word of the Haskins sentence, on that place's articulator: TT, TD, or the lips)
and its MVIEW-style gesture landmarks (:mod:`tonguevis.preprocess.gestures`: GONS, PVEL, NONS,
MAXC, NOFFS, PVEL2, GOFFS, VTARG).  Positions are head-corrected (the caller passes the recording
as :func:`tonguevis.workflows.head_corrected` gives it), millimetres, x anterior, y left, z up.

Definitions (:data:`COLUMNS`; units in every name):

* ``closure_s``: MAXC, the lowest 3-D speed within 50 ms of the highest position.
* ``constriction_degree_mm``: the shortest 3-D distance from the articulator's sensor (raw
  sample at MAXC) to the palate surface, negative when the sensor is above it
  (:mod:`tonguevis.analysis.constriction`; MVIEW's ``MDP_PALDIST``); ``constriction_location_mm``:
  where the closest palate point lies along the palate's midline, from its front;
  ``constriction_at_palate_edge``: that point is on the palate's boundary (the sensor is beyond
  the palate's extent; the distance is to its edge).  Tongue sensors only (NaN for the lips).
* ``peak_velocity_closing_mm_s`` / ``_opening_``: the 3-D tangential speed of the sensor low-passed
  at 12 Hz at PVEL / PVEL2 (for the lips: the speed of the lip aperture).
* ``displacement_closing_mm``: the 3-D distance between the low-passed positions at GONS and MAXC
  (MVIEW's PD); ``displacement_opening_mm``: MAXC to GOFFS (PD2); for the lips, the change of aperture.
* ``stiffness_closing_per_s`` / ``_opening_``: peak velocity / displacement, "a kinematic index of
  mass-normalised stiffness" (Munhall, Ostry & Parush 1985, JEP:HPP 11:457); not the
  time-to-peak-velocity variant.
* ``lip_aperture_mm``: the 3-D UL-LL distance at MAXC; ``lip_protrusion_mm``: the lips' midpoint's
  x at MAXC minus its rest value (forward positive), when UL and LL exist.
* ``jaw_opening_mm``: the jaw sensor's 3-D distance from its rest position at MAXC, negative when
  it is above its rest; ``jaw_opening_vowel_mm`` the same at the vowel target (VTARG).
* durations (ms): the production (start to end), the gesture (GONS-GOFFS), closing (GONS-NONS),
  nucleus (NONS-NOFFS), opening (NOFFS-GOFFS).
"""

from __future__ import annotations

import math

import numpy as np

#: Column name -> kind ("str", "int", "float", "bool"), in order.
COLUMNS: dict[str, str] = {
    "production": "str", "train": "int", "index": "int", "label": "str", "articulator": "str",
    "start_s": "float", "end_s": "float", "duration_ms": "float", "closure_s": "float", "gons_s": "float",
    "goffs_s": "float",
    "constriction_degree_mm": "float", "constriction_location_mm": "float", "constriction_at_palate_edge": "bool",
    "peak_velocity_closing_mm_s": "float", "peak_velocity_opening_mm_s": "float",
    "displacement_closing_mm": "float", "displacement_opening_mm": "float",
    "stiffness_closing_per_s": "float", "stiffness_opening_per_s": "float",
    "lip_aperture_mm": "float", "lip_protrusion_mm": "float", "jaw_opening_mm": "float",
    "jaw_opening_vowel_mm": "float",
    "gesture_duration_ms": "float", "closing_duration_ms": "float", "nucleus_duration_ms": "float",
    "opening_duration_ms": "float", "fallbacks": "str", "palate": "str",
}
#: The columns a reader most wants, in the order the CLI prints them.
SHOWN = ("production", "label", "articulator", "closure_s", "constriction_degree_mm", "constriction_location_mm",
         "peak_velocity_closing_mm_s", "displacement_closing_mm", "stiffness_closing_per_s",
         "peak_velocity_opening_mm_s", "lip_aperture_mm", "jaw_opening_mm")
NAN = float("nan")


def production_articulator(production, table, available: list[str]) -> str:
    """The articulator a production is measured on: for labelled productions the place its label names
    (``birch``: the lips, ``smooth``: the tip) when that articulator exists, else the table's."""
    from tonguevis.preprocess.articulators import ARTICULATOR_OF_PLACE, place_of

    if table.articulator_reason == "labelled":
        choice = ARTICULATOR_OF_PLACE.get(place_of(production.label) or "")
        if choice in available:
            return choice
    return production.articulator or table.articulator


def _index(times: np.ndarray, t: float) -> int | None:
    """The sample nearest time ``t`` (None for NaN)."""
    if not math.isfinite(t):
        return None
    i = int(np.searchsorted(times, t))
    if i > 0 and (i == len(times) or abs(times[i - 1] - t) <= abs(times[i] - t)):
        i -= 1
    return i


def _distance(a, b) -> float:
    return float(np.linalg.norm(np.asarray(a) - np.asarray(b))) if np.isfinite(a).all() and np.isfinite(b).all() \
        else NAN


def _ratio(num: float, den: float) -> float:
    return num / den if math.isfinite(num) and math.isfinite(den) and den > 0 else NAN


def _jaw_opening(jaw: np.ndarray, rest: np.ndarray) -> float:
    """mm from rest, negative when above it."""
    d = jaw - rest
    if not np.isfinite(d).all():
        return NAN
    return float(1e3 * np.linalg.norm(d) * (-1.0 if d[2] > 0 else 1.0))


def production_measures(recording, table, palate=None, palate_label: str = "",
                        rest: dict[str, np.ndarray] | None = None) -> list[dict]:
    """One dict per production of ``table`` (keys: :data:`COLUMNS`), see the module docstring.

    recording : head-corrected (metres); table : its ProductionTable; palate : a
    :class:`~tonguevis.palate.PalateSurface` in the recording's frame, or None (no constriction);
    palate_label : what the ``palate`` column says; rest : {sensor: (3,) m} rest positions of JAW,
    UL, LL (None: no jaw opening or lip protrusion).
    """
    from tonguevis.analysis.constriction import constriction
    from tonguevis.preprocess.articulators import LIP_APERTURE, available, constriction_signal
    from tonguevis.preprocess.productions import labelled_measures

    times = recording.times
    options = available(recording)
    signals: dict[str, object] = {}
    rest = rest or {}
    rows, closures = [], []
    for production, marks in zip(table.productions, table.landmarks):
        articulator = production_articulator(production, table, options)
        if articulator and articulator not in signals and (articulator == LIP_APERTURE or
                                                           articulator in recording.sensors):
            signals[articulator] = constriction_signal(recording, articulator)
        signal = signals.get(articulator)
        if articulator != (production.articulator or table.articulator) and signal is not None:
            marks = labelled_measures(recording, signal, production.start, production.end)[2]
        row = {"production": f"{production.train}.{production.index}", "train": production.train,
               "index": production.index, "label": production.label, "articulator": articulator,
               "start_s": production.start, "end_s": production.end,
               "duration_ms": 1e3 * (production.end - production.start),
               "fallbacks": " ".join(marks.fallbacks), "palate": palate_label if palate is not None else ""}
        at = {k: _index(times, t) for k, t in marks.times.items()}
        row.update(closure_s=marks.times["maxc"], gons_s=marks.times["gons"], goffs_s=marks.times["goffs"],
                   peak_velocity_closing_mm_s=1e3 * marks.peak_velocity,
                   peak_velocity_opening_mm_s=1e3 * marks.peak_velocity2)
        for name, seconds in marks.durations().items():
            row[f"{name}_duration_ms"] = 1e3 * seconds
        if articulator == LIP_APERTURE and signal is not None and None not in (at["gons"], at["maxc"], at["goffs"]):
            s = signal.signal
            closing, opening = 1e3 * abs(s[at["maxc"]] - s[at["gons"]]), 1e3 * abs(s[at["goffs"]] - s[at["maxc"]])
        else:
            closing = 1e3 * _distance(marks.positions["maxc"], marks.positions["gons"])
            opening = 1e3 * _distance(marks.positions["goffs"], marks.positions["maxc"])
        row.update(displacement_closing_mm=closing, displacement_opening_mm=opening,
                   stiffness_closing_per_s=_ratio(row["peak_velocity_closing_mm_s"], closing),
                   stiffness_opening_per_s=_ratio(row["peak_velocity_opening_mm_s"], opening))
        closure = at["maxc"]
        lips = "UL" in recording.sensors and "LL" in recording.sensors
        row.update(lip_aperture_mm=NAN, lip_protrusion_mm=NAN, jaw_opening_mm=NAN, jaw_opening_vowel_mm=NAN)
        if closure is not None and lips:
            upper, lower = recording.sensors["UL"][closure], recording.sensors["LL"][closure]
            row["lip_aperture_mm"] = 1e3 * _distance(upper, lower)
            if "UL" in rest and "LL" in rest:
                row["lip_protrusion_mm"] = 1e3 * (0.5 * (upper[0] + lower[0]) - 0.5 * (rest["UL"][0] + rest["LL"][0]))
        if "JAW" in recording.sensors and "JAW" in rest:
            jaw = recording.sensors["JAW"]
            if closure is not None:
                row["jaw_opening_mm"] = _jaw_opening(jaw[closure], rest["JAW"])
            if at["vowel"] is not None:
                row["jaw_opening_vowel_mm"] = _jaw_opening(jaw[at["vowel"]], rest["JAW"])
        rows.append(row)
        sensor = articulator if articulator in recording.sensors else None
        closures.append(recording.sensors[sensor][closure] if sensor is not None and closure is not None
                        else np.full(3, np.nan))
    for row in rows:
        row.update(constriction_degree_mm=NAN, constriction_location_mm=NAN, constriction_at_palate_edge=None)
    if palate is not None and rows:
        found = constriction(palate, np.array(closures))
        for row, degree, location, edge in zip(rows, found.degree, found.location, found.at_edge):
            if math.isfinite(degree):
                row.update(constriction_degree_mm=1e3 * float(degree), constriction_location_mm=1e3 * float(location),
                           constriction_at_palate_edge=bool(edge))
    return rows


def measures_text(rows: list[dict], columns=SHOWN) -> str:
    """A fixed-width table of ``rows`` for the terminal (the columns ``columns``; NaN as '-')."""
    widths = [max(len(c), 7) for c in columns]
    lines = [" ".join(f"{c:>{w}}" for c, w in zip(columns, widths))]
    for row in rows:
        cells = []
        for column, width in zip(columns, widths):
            value = row.get(column)
            if isinstance(value, bool):
                cells.append(f"{'yes' if value else 'no':>{width}}")
            elif isinstance(value, str) or value is None:
                cells.append(f"{value or '-':>{width}}")
            elif isinstance(value, (int, np.integer)) and not isinstance(value, bool):
                cells.append(f"{value:>{width}d}")
            elif not math.isfinite(float(value)):
                cells.append(f"{'-':>{width}}")
            else:
                digits = 3 if column.endswith("_s") else 1 if abs(value) >= 100 else 2
                cells.append(f"{float(value):>{width}.{digits}f}")
        lines.append(" ".join(cells))
    return "\n".join(lines)


def write_measures(rows: list[dict], path) -> object:
    """Write the measures table: Parquet for ``.parquet``, else CSV (units in every column name); atomically."""
    from tonguevis.preprocess.gesture_table import write_rows

    return write_rows(rows, COLUMNS, path)
