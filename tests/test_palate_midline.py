"""The palate's midline from its own mirror symmetry (the lateral tongue sensors, pushed aside by the
probe while tracing, put it millimetres off on real traces)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tonguevis.palate import fit_palate, symmetry_midline

OPTI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ema" / "optispeech"


def _vault(y0: float, ys: np.ndarray, xs: np.ndarray) -> np.ndarray:
    """Points on a vault symmetric about y = y0 (m): 12 mm high, falling off as a parabola."""
    gx, gy = np.meshgrid(xs, ys)
    z = 0.012 - 40.0 * (gy - y0) ** 2 - 5.0 * (gx + 0.01) ** 2
    return np.column_stack([gx.ravel(), gy.ravel(), z.ravel()])


def test_an_unevenly_traced_vault_gives_its_own_midline_not_the_points_median():
    rng = np.random.default_rng(3)
    y0 = 0.004
    # traced densely on the left, sparsely on the right: the median y lies well left of the midline
    ys = np.concatenate([np.linspace(y0, y0 + 0.015, 40), np.linspace(y0 - 0.012, y0, 8)])
    points = _vault(y0, ys, np.linspace(-0.03, 0.01, 25))
    points[:, 2] += rng.normal(0.0, 2e-4, len(points))
    assert abs(np.median(points[:, 1]) - y0) > 0.003
    found = symmetry_midline(points)
    assert found is not None and abs(found - y0) < 5e-4
    surface = fit_palate(points)
    assert surface.metadata["midline_from"] == "the traces' mirror symmetry"
    assert abs(surface.metadata["midline_y"] - y0) < 5e-4


def test_one_side_traced_cannot_tell_and_says_so():
    points = _vault(0.0, np.linspace(0.004, 0.015, 20), np.linspace(-0.03, 0.01, 20))
    assert symmetry_midline(points) is None
    assert fit_palate(points).metadata["midline_from"] == "the trace points' median"
    assert fit_palate(points, midline_y=0.0).metadata["midline_from"] == "given"


@pytest.mark.skipif(not OPTI.exists(), reason=f"the shared Opti-Speech traces are not at {OPTI}")
def test_on_the_real_traces_the_symmetry_fits_better_than_the_lateral_sensors():
    from tonguevis.palate import midline_of
    from tonguevis.workflows import open_recording
    from tonguevis.workflows.palate import palate_from_traces

    traces = sorted(OPTI.glob("00[234]_*.tsv"))
    surface = palate_from_traces(traces)
    assert surface.metadata["midline_from"] == "the traces' mirror symmetry"
    lateral = float(np.mean([midline_of(open_recording(p)) for p in traces]))
    # the coronal trace's crest lies 5-5.5 mm right of the head frame's origin; the lateral sensors say 8.3
    assert -0.0068 < surface.metadata["midline_y"] < -0.0048 and lateral < -0.0075
    from tonguevis.palate import trace_points
    from tonguevis.preprocess.correction import head_corrected

    points = np.concatenate([trace_points(head_corrected(open_recording(p)), "PROBE") for p in traces])
    by_sensors = fit_palate(points, midline_y=lateral)
    assert surface.metadata["rms_m"] < by_sensors.metadata["rms_m"]
