"""The deterministic parts of scripts/build_meshes.py (the fTetWild stage is not
bit-reproducible, so the shipped mesh itself is tested in test_default_mesh.py)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from tonguevis.paths import REPO_DIR


@pytest.fixture(scope="module")
def build():
    pytest.importorskip("trimesh")
    spec = importlib.util.spec_from_file_location("build_meshes", REPO_DIR / "scripts" / "build_meshes.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_field_follows_the_profiles(build):
    f = build.tongue_field
    # inside the body, outside below the blade, outside beyond tip and root
    assert f(np.array(40.0), np.array(0.0), np.array(25.0)) < 0
    assert f(np.array(8.0), np.array(0.0), np.array(20.0)) > 0      # the free blade's underside
    assert f(np.array(-1.0), np.array(0.0), np.array(45.0)) > 0
    assert f(np.array(build.LENGTH + 1), np.array(0.0), np.array(15.0)) > 0
    # the dorsum crosses zero at the TOP_Z height on the midline
    zs = np.linspace(40, 60, 2001)
    top = zs[np.nonzero(f(np.full_like(zs, 40.0), np.zeros_like(zs), zs) < 0)[0].max()]
    assert top == pytest.approx(np.interp(40.0, *np.array(build.TOP_Z).T), abs=0.05)
    # symmetric about y = 0
    rng = np.random.default_rng(0)
    s, y, z = rng.uniform(0, 76, 200), rng.uniform(0, 35, 200), rng.uniform(0, 56, 200)
    np.testing.assert_array_equal(f(s, y, z), f(s, -y, z))


def test_context_surfaces_are_closed_and_clear_of_the_tongue_tip(build):
    jaw, palate = build.jaw_surface(), build.palate_surface()
    assert jaw.is_watertight and jaw.volume > 0
    assert palate.is_watertight and palate.volume > 0
    assert jaw.vertices[:, 0].max() > 3.0                        # incisors ahead of the tip (x = 0)
    assert palate.vertices[:, 2].min() > 45.0                    # the vault stays above the blade
