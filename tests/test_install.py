"""The README's two install commands (issue 37, item 1): the first installs the app and every command
a user runs and no test or lint tool; the second adds the developer's tools and is what CI runs."""

from __future__ import annotations

import ast
import importlib.metadata as metadata
import importlib.util
import re
import sys
import tomllib

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from tonguevis.paths import REPO_DIR

PROJECT = tomllib.loads((REPO_DIR / "pyproject.toml").read_text(encoding="utf-8"))["project"]
README = (REPO_DIR / "README.md").read_text(encoding="utf-8")
#: What a clinician never needs: the test runner and its plugins, the lints, property tests.
DEVELOPER_TOOLS = {"pytest", "pytest-qt", "pytest-timeout", "pytest-xvfb", "hypothesis", "ruff", "import-linter"}


def readme_install_commands() -> list[str]:
    """The README's ``pip install`` lines, in order."""
    blocks = re.findall(r"```bash\n(.*?)```", README, flags=re.S)
    return [line.strip() for block in blocks for line in block.splitlines() if "pip install" in line]


def extras_of(command: str) -> set[str]:
    """The extras ``command`` installs this project with: ``pip install -e ".[app]"`` -> {"app"}."""
    found = re.search(r'-e\s+"?\.(?:\[([\w,-]+)\])?"?', command)
    assert found, f"not an install of this clone: {command}"
    return set(found.group(1).split(",")) if found.group(1) else set()


def _installed_requirements(name: str, extras: set[str]) -> list[Requirement]:
    """An installed distribution's own requirements with ``extras``; none when it is not installed."""
    try:
        lines = metadata.requires(name) or []
    except metadata.PackageNotFoundError:
        return []
    found = []
    for line in lines:
        requirement = Requirement(line)
        marker = requirement.marker
        if marker is None or any(marker.evaluate({"extra": e}) for e in extras | {""}):
            found.append(requirement)
    return found


def distributions_installed_by(extras: set[str], transitive: bool = True) -> set[str]:
    """Canonical names of the distributions ``pip install -e ".[extras]"`` brings: this project's own
    requirements from its pyproject.toml (not the installed copy's), then theirs from their metadata."""
    own = PROJECT["optional-dependencies"]
    pending = [Requirement(r) for r in PROJECT["dependencies"]]
    done_extras: set[str] = set()
    todo = set(extras)
    while todo:
        extra = todo.pop()
        done_extras.add(extra)
        for line in own[extra]:
            requirement = Requirement(line)
            if canonicalize_name(requirement.name) == "tonguevis":
                todo |= requirement.extras - done_extras
            else:
                pending.append(requirement)
    seen: dict[str, set[str]] = {}
    while pending:
        requirement = pending.pop()
        name = canonicalize_name(requirement.name)
        if name in seen and requirement.extras <= seen[name]:
            continue
        seen.setdefault(name, set()).update(requirement.extras)
        if transitive:
            pending.extend(_installed_requirements(name, seen[name]))
    return set(seen)


def third_party_imports() -> set[str]:
    """Every module the package imports from outside the standard library, dotted as written."""
    found = set()
    for path in (REPO_DIR / "tonguevis").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            found |= {n for n in names if n.split(".")[0] not in sys.stdlib_module_names | {"tonguevis"}}
    return found


def providers(module: str) -> set[str]:
    """The distributions that could provide ``module``: the one holding its file when the package is
    split across several (PySide6's QtMultimedia is in PySide6-Addons, QtCore in PySide6-Essentials)."""
    top = module.split(".")[0]
    candidates = {canonicalize_name(d) for d in metadata.packages_distributions().get(top, [])}
    if len(candidates) <= 1 or "." not in module:
        return candidates
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        return candidates
    for name in candidates:
        files = metadata.distribution(name).files or []
        if any(str(f.locate()) == spec.origin for f in files):
            return {name}
    return candidates


def test_the_readme_installs_the_app_first_and_the_developer_tools_second():
    commands = readme_install_commands()
    assert len(commands) >= 2
    first, second = commands[0], commands[1]
    assert first.endswith("&& tonguevis"), "the first command installs, then opens the app"
    assert second.endswith("&& python -m pytest")
    app = distributions_installed_by(extras_of(first))
    dev = distributions_installed_by(extras_of(second))
    assert not app & DEVELOPER_TOOLS, f"the app's install brings {sorted(app & DEVELOPER_TOOLS)}"
    assert DEVELOPER_TOOLS <= dev
    assert app <= dev, "the test suite runs the app: the second install holds the first"


def test_the_apps_install_brings_every_module_the_package_imports():
    """The app, `export-video` (imageio-ffmpeg), the batch (joblib, Dask distributed), ...: a command
    a user runs never stops on a module the README's first command did not install."""
    app = distributions_installed_by(extras_of(readme_install_commands()[0]))
    missing = {}
    for module in sorted(third_party_imports()):
        found = providers(module)
        if not found:
            pytest.skip(f"{module} is not installed here, so its distribution is unknown")
        if not found & app:
            missing[module] = sorted(found)
    assert not missing, f"imported by tonguevis, not installed by the README's first command: {missing}"


def test_the_readmes_test_command_is_what_ci_runs_last():
    ci = [line.strip() for line in (REPO_DIR / ".ci" / "run").read_text(encoding="utf-8").splitlines()]
    last = [line for line in ci if line and not line.startswith("#")][-1]
    assert last == readme_install_commands()[1]
    assert all(extras_of(line) == extras_of(last) for line in ci if "pip install" in line and " -e " in line)
