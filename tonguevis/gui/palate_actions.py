"""File ▸ Load palate… / Fit palate from traces… / generic / no palate: the window's palate actions.

The palate the window simulates against is ``window.palate`` (None: no contact,
the generic palate drawn only; "generic"; or a speaker's
:class:`~tonguevis.palate.PalateSurface`, in the recordings' frame).  Choosing
one re-simulates the open recording with it (contact on); it becomes the
window's palate only once that simulation succeeded, so a palate that does not
fit the recording leaves what was shown as it was.  It stays for the next
recordings opened (a palate trace belongs to a session, whose recordings share it).
"""

from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import QFileDialog, QInputDialog

from tonguevis.errors import TonguevisError

__all__ = ["PalateMixin", "read_palate"]

PALATE_FILTER = "Palate surfaces (*.stl *.obj *.ply *.vtk *.vtu *.off *.npz);;All files (*)"


def read_palate(path):
    """A palate file (``tonguevis palate``'s mesh with its grid, any surface mesh, or the shipped one)
    read and checked; PalateError naming the file and the problem otherwise."""
    from tonguevis.palate import PalateError, load_palate

    path = Path(path)
    if not path.exists():
        raise PalateError("no such file", path)
    return load_palate(path)


class PalateMixin:
    """Needs the window's ``palate``, ``session``, ``state``, ``controller``, ``show_error``."""

    def ask_load_palate(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Load the speaker's palate (from tonguevis palate)",
                                              str(self._last_folder()), PALATE_FILTER)
        if path:
            self.load_palate(path)

    def load_palate(self, path) -> bool:
        """Read ``path`` (a bad file: a dialog naming it and the problem) and re-simulate with it."""
        try:
            surface = read_palate(path)
        except (TonguevisError, OSError) as exc:
            self.show_error("Cannot load palate", str(exc), path)
            return False
        self.use_palate(surface)
        return True

    def use_generic_palate(self) -> None:
        self.use_palate("generic")

    def use_no_palate(self) -> None:
        self.use_palate(None)

    def use_palate(self, palate) -> None:
        """Simulate the open recording against ``palate`` (None: without contact); it becomes the
        window's palate when that succeeds (at once when no recording is open)."""
        if self.session is None:
            self.palate = palate
            self.state.set_status(f"palate for the next recording: {self._palate_name(palate)}", self)
            return
        self.controller.try_settings(palate=palate)

    @staticmethod
    def _palate_name(palate) -> str:
        from tonguevis.gui.controller import palate_name

        return palate_name(palate)

    # -- fitting ----------------------------------------------------------------------
    def ask_fit_palate(self) -> None:
        paths, _ = QFileDialog.getOpenFileNames(
            self, "Palate-trace recordings (a probe sensor drawn along the palate)", str(self._last_folder()))
        if not paths:
            return
        probe = self._ask_probe(paths[0])
        if probe is None:
            return
        out, _ = QFileDialog.getSaveFileName(self, "Save the fitted palate", str(Path(paths[0]).with_name("palate.stl")),
                                             "Surface meshes (*.stl *.obj *.ply *.vtk)")
        if out:
            self.fit_palate(paths, out, probe)

    def _ask_probe(self, first) -> str | None:
        """The probe sensor: PROBE when the first trace has it, else the user picks one of its sensors."""
        from tonguevis.workflows.recording import open_recording

        try:
            names = open_recording(first, audio=False).sensor_names
        except (TonguevisError, OSError) as exc:
            self.show_error("Cannot read palate trace", str(exc), first)
            return None
        if "PROBE" in names:
            return "PROBE"
        name, ok = QInputDialog.getItem(self, "Probe sensor", f"Which sensor of {Path(first).name} traced the palate?",
                                        list(names), 0, False)
        return name if ok else None

    def fit_palate(self, traces, out, probe: str = "PROBE", sensor_map=None) -> None:
        """Fit a palate to ``traces`` in a job (progress, cancel), save it at ``out`` and simulate with it."""
        from tonguevis.gui.export import run_with_progress
        from tonguevis.workflows.palate import palate_from_traces

        out = Path(out)
        if not out.suffix:
            out = out.with_suffix(".stl")
        traces = [Path(t) for t in traces]

        def work(progress):
            surface = palate_from_traces(traces, probe, sensor_map, progress=progress)
            out.parent.mkdir(parents=True, exist_ok=True)
            surface.save(out)
            surface.metadata["file"] = str(out)
            return surface

        def fitted(surface) -> None:
            meta = surface.metadata
            self.state.set_status(
                f"palate fitted to {meta['kept']} of {meta['points']} trace points (RMS {1e3 * meta['rms_m']:.2f} mm), "
                f"saved as {out}", self)
            self.use_palate(surface)

        self.export_job = run_with_progress(self, "Palate fit", work, f"palate saved as {out}", traces[0],
                                            on_success=fitted)
