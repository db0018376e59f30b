"""The analyses compute with NumPy and SciPy only: pictures live in tonguevis.render.

Importing :mod:`tonguevis.analysis` and every one of its submodules must load
neither a plotting library (matplotlib, pyvista, VTK) nor Qt; and no analysis
module names a third-party package other than NumPy and SciPy anywhere in its
source, not even inside a function (a lazy import is still a dependency).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import tonguevis

ANALYSIS = Path(tonguevis.__file__).parent / "analysis"
#: Top-level packages an analysis module may never load.
FORBIDDEN = ("matplotlib", "pyvista", "pyvistaqt", "vtk", "vtkmodules", "PySide6", "PySide2", "PyQt5", "PyQt6",
             "qtpy", "imageio", "imageio_ffmpeg", "PIL")
ALLOWED_THIRD_PARTY = {"numpy", "scipy"}
#: Known exceptions, file formats rather than pictures: SegmentationResult.to_vtu writes with meshio
#: (imported in the method).  To move to tonguevis.io; listed here so no new one slips in.
EXCEPTIONS = {"segmentation/result.py": {"meshio"}}


def _analysis_modules() -> list[str]:
    names = []
    for path in sorted(ANALYSIS.rglob("*.py")):
        parts = list(path.relative_to(ANALYSIS.parent.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names.append(".".join(parts))
    return names


def test_importing_the_analyses_loads_no_plotting_library_nor_qt():
    code = textwrap.dedent(
        f"""
        import importlib, json, sys
        failed = {{}}
        for name in {_analysis_modules()!r}:
            try:
                importlib.import_module(name)
            except Exception as exc:
                failed[name] = repr(exc)
        loaded = sorted({{m.split(".")[0] for m in sys.modules}} & set({FORBIDDEN!r}))
        ours = sorted(m for m in sys.modules if m.startswith(("tonguevis.render", "tonguevis.gui")))
        print(json.dumps({{"failed": failed, "loaded": loaded, "ours": ours}}))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=180)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["failed"] == {}
    assert report["loaded"] == [], f"importing tonguevis.analysis loaded {report['loaded']}"
    assert report["ours"] == [], f"tonguevis.analysis imports the app or the pictures: {report['ours']}"


def _imported_packages(path: Path) -> set[str]:
    """Top-level names of every absolute import in a file, wherever it stands (functions too)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_no_analysis_module_names_a_package_beyond_numpy_and_scipy():
    stdlib = set(sys.stdlib_module_names)
    offenders = {}
    for path in sorted(ANALYSIS.rglob("*.py")):
        name = path.relative_to(ANALYSIS).as_posix()
        extra = _imported_packages(path) - stdlib - ALLOWED_THIRD_PARTY - {"tonguevis"} - EXCEPTIONS.get(name, set())
        if extra:
            offenders[name] = sorted(extra)
    assert offenders == {}
    # and none reaches for the app or the pictures through tonguevis
    for path in sorted(ANALYSIS.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        assert "tonguevis.render" not in text.replace(":mod:`tonguevis.render", "") and "tonguevis.gui" not in text, path


def test_the_check_sees_a_lazy_import(tmp_path):
    """The source check would catch matplotlib imported inside a function (the old energy_plot.py did)."""
    module = tmp_path / "lazy.py"
    module.write_text("def plot(ax):\n    import matplotlib\n    from pyvista import Plotter\n")
    assert _imported_packages(module) == {"matplotlib", "pyvista"}
