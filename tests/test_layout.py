"""The house's layout (issue 24): gui/ is Qt only, the layers import downward, no cycles between packages.

import-linter checks the contracts in pyproject.toml in CI; these tests say the same from the
import graph (grimp, import-linter's engine) so a plain ``pytest`` catches a break too.
"""

from __future__ import annotations

import pytest

grimp = pytest.importorskip("grimp", reason="grimp comes with import-linter (the test extra)")

QT = ("PySide6", "pyvistaqt")
#: The packages of tonguevis, top layer first: each may import only those after it.
LAYERS = ("cli", "gui", "batch", "live", "appstate", "workflows", "render", "analysis", "sim", "palate",
          "preprocess", "mesh", "io")


@pytest.fixture(scope="module")
def graph():
    # no cache: a stale .grimp_cache hid an import cycle from this test locally (2026-12-07) that CI then found
    return grimp.build_graph("tonguevis", include_external_packages=True, exclude_type_checking_imports=True,
                             cache_dir=None)


def _package(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "tonguevis" else None


def test_every_gui_module_is_qt(graph):
    """gui/ holds Qt code only: each module imports Qt, directly or through another gui module."""
    gui = sorted(m for m in graph.modules if m.startswith("tonguevis.gui.") or m == "tonguevis.gui")
    qt_free = []
    for module in gui:
        if module == "tonguevis.gui":  # the package's docstring only
            continue
        reaches = set(graph.find_upstream_modules(module)) | graph.find_modules_directly_imported_by(module)
        if not any(r.split(".")[0] in QT for r in reaches):
            qt_free.append(module)
    assert qt_free == [], f"Qt-free code belongs in render/ or workflows/: {qt_free}"


def test_the_core_reaches_no_qt(graph):
    """Nothing outside gui/ and cli/ reaches PySide6 or pyvistaqt, not even through another module."""
    offenders = []
    for module in graph.modules:
        package = _package(module)
        if package is None or package in ("gui", "cli"):
            continue
        reaches = set(graph.find_upstream_modules(module))
        if any(r.split(".")[0] in QT for r in reaches):
            offenders.append(module)
    assert offenders == []


def test_layers_import_downward_only(graph):
    """A package imports only packages below it in LAYERS (cli and gui at the top, io at the bottom)."""
    rank = {name: k for k, name in enumerate(LAYERS)}
    upward = []
    for module in graph.modules:
        package = _package(module)
        if package not in rank:
            continue
        for imported in graph.find_modules_directly_imported_by(module):
            other = _package(imported)
            if other in rank and other != package and rank[other] < rank[package]:
                upward.append(f"{module} -> {imported}")
    assert upward == []


def test_export_video_is_in_a_qt_free_package():
    """``tonguevis export-video`` renders with render/ (headless); the proof that no Qt loads is
    tests/test_export_video_headless.py."""
    import tonguevis.cli.export_video as command

    source = open(command.__file__).read()
    assert "tonguevis.gui" not in source


def _import_cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative): each holds a cycle."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))
    return cycles


def test_the_cycle_finder_finds_a_cycle_and_only_one():
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _import_cycles(edges) == [["a", "b", "c"]]
    assert _import_cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_at_any_depth():
    """No module reaches itself through its imports, counting every import: the module-level ones, those inside
    functions and those under TYPE_CHECKING (issue 34: there were cycles in mesh/, between preprocess/ and sim/,
    inside sim/, workflows/ and gui/)."""
    every = grimp.build_graph("tonguevis", exclude_type_checking_imports=False, cache_dir=None)
    modules = {m for m in every.modules if m.startswith("tonguevis")}
    edges = {m: {i for i in every.find_modules_directly_imported_by(m) if i in modules} for m in modules}
    assert _import_cycles(edges) == []
