"""What tonguevis writes, in one table that ``tonguevis formats`` prints and the app's File ▸ Export menu is built from.

Each :class:`ExportFormat` says what a file holds (units, frame of reference), which command
writes it and where the app does; :func:`write_export` writes the formats that need only a
simulated session (no window, no Qt): the MP4, the VTK series, the XDMF, the productions as
CSV and as a TextGrid, the EMA as a multichannel WAV for Praat.  The PNG of the app is a picture of its window (the app writes it);
``tonguevis view --screenshot`` writes the same from the command line.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from tonguevis._progress import ProgressCallback
from tonguevis.errors import TonguevisError


@dataclass(frozen=True)
class ExportFormat:
    """One thing tonguevis writes.

    key : short name (``--list``, the app's menu); title : the menu's words;
    suffix : the file's ending ("/" for a folder); holds : what is in it (units, frame);
    command : how the command line writes it; needs_motion : only after a simulation.
    """

    key: str
    title: str
    suffix: str
    holds: str
    command: str
    needs_motion: bool = True


EXPORTS: tuple[ExportFormat, ...] = (
    ExportFormat("png", "Screenshot (PNG)", ".png",
                 "the window as shown: the four 3D views, the sensor panel, the sound",
                 "tonguevis view FILE --screenshot OUT.png", needs_motion=False),
    ExportFormat("mp4", "Video (MP4)", ".mp4",
                 "the 3D views over a time span with the recording's sound (H.264, AAC); the frame of "
                 "reference and the colouring written on every picture",
                 "tonguevis export-video FILE --out OUT.mp4"),
    ExportFormat("xdmf", "Motion for ParaView (XDMF + HDF5)", ".xdmf",
                 "the mesh once and every frame's displacement (m, float32) in one .h5 beside it; the app's "
                 "also the energy density (J/m³) it colours by",
                 "tonguevis simulate FILE --out DIR --paraview"),
    ExportFormat("vtk", "Motion as a VTK series (one file per frame)", "/",
                 "motion.pvd and frame_XXXXX.vtu: displacement and deformation (m), the app's also the energy "
                 "density (J/m³); README.txt and jaw_offset.csv say the frame",
                 "tonguevis simulate FILE --out DIR --vtk-series"),
    ExportFormat("csv", "Productions (CSV)", ".csv",
                 "one row per CV production: start, closure, release, end (s), the articulator and the gesture "
                 "landmarks, units in the header",
                 "tonguevis syllables FILE --csv OUT.csv", needs_motion=False),
    ExportFormat("textgrid", "Productions for Praat (TextGrid)", ".TextGrid",
                 "the productions as an interval tier and their landmarks as point tiers, with the recording's "
                 "own label tiers",
                 "tonguevis syllables FILE --textgrid OUT.TextGrid", needs_motion=False),
    ExportFormat("wav", "EMA for Praat (multichannel WAV)", ".wav",
                 "the sound and every sensor's x, y, z (mm, head-corrected) as float32 channels at the sound's rate "
                 "(16 kHz without one); OUT.json beside it names each channel and its scale",
                 "tonguevis export-wav FILE --out OUT.wav", needs_motion=False),
)


def export_format(key: str) -> ExportFormat:
    """The :class:`ExportFormat` called ``key``; an unknown one is a TonguevisError listing them."""
    for fmt in EXPORTS:
        if fmt.key == key:
            return fmt
    raise TonguevisError(f"unknown export {key!r}; tonguevis writes {', '.join(f.key for f in EXPORTS)}")


def exports_text() -> str:
    """The table as ``tonguevis formats`` prints it: one block per format."""
    lines = []
    for fmt in EXPORTS:
        lines.append(f"{fmt.key:<9} {fmt.title} ({fmt.suffix if fmt.suffix != '/' else 'a folder'})")
        lines.append(f"{'':<9} {fmt.holds}")
        lines.append(f"{'':<9} command line: {fmt.command}")
        lines.append(f"{'':<9} app: File ▸ Export ▸ {fmt.title}")
    return "\n".join(lines)


def write_export(key: str, session, out: str | os.PathLike, progress: ProgressCallback | None = None,
                 **options) -> Path:
    """Write ``session`` as export ``key`` at ``out``; returns what was written.

    ``options`` go to the writer: mp4 (``start``, ``end``, ``mode``, ``frame``, ``fps``, ``size``),
    xdmf (``frame``, ``surface_only``, ``stride``), vtk (``frame``).  The PNG is the app's window
    (:mod:`tonguevis.gui.export`) or ``tonguevis view --screenshot``: not written here.
    """
    fmt = export_format(key)
    if fmt.needs_motion and getattr(session, "motion", None) is None:
        raise TonguevisError(f"{fmt.title}: simulate the recording first", getattr(session, "path", None))
    if key == "mp4":
        from tonguevis.render.video import export_video

        return export_video(session, out, progress=progress, **options)
    if key == "xdmf":
        from tonguevis.render.paraview import export_paraview

        return export_paraview(session, out, progress=progress, **options)
    if key == "vtk":
        from tonguevis.render.video import export_vtk_series

        return export_vtk_series(session, out, progress=progress, **options)
    if key == "csv":
        table = _production_table(session)
        motion = getattr(session, "motion", None)
        if motion is None or getattr(motion, "palate", None) is None:
            table.to_csv(out)
            return Path(out)
        # Simulated against a palate: each production's palatogram at its closure beside it (tonguevis.analysis.epg).
        from tonguevis.analysis.epg import production_epg
        from tonguevis.preprocess.gesture_table import write_rows
        from tonguevis.preprocess.productions import CSV_COLUMNS

        kinds = {"train": "int", "index": "int", "label": "str", "articulator": "str"}
        rows = [{**dict(zip(CSV_COLUMNS, row)), **epg} for row, epg in zip(table.rows(), production_epg(motion, table))]
        columns = {c: kinds.get(c, "float") for c in CSV_COLUMNS}
        columns.update({c: "float" for c in rows[0] if c not in columns} if rows else {})
        return write_rows(rows, columns, out)
    if key == "wav":
        from tonguevis.workflows.ema_wav import write_ema_wav

        return write_ema_wav(session.recording, out)[0]
    if key == "textgrid":
        from tonguevis.preprocess.labelled import write_productions_textgrid

        write_productions_textgrid(out, _production_table(session), session.recording)
        return Path(out)
    raise TonguevisError(f"{fmt.title} is a picture of the app's window: File ▸ Export in the app, or "
                         f"{fmt.command}")


def _production_table(session):
    table = getattr(session, "production_table", None)
    if table is None:
        raise TonguevisError("no productions found in this recording", getattr(session, "path", None))
    return table
