"""The virtual electropalatograph (issue 36): the Reading layout, the indices against the definitions written
out, the surface lookup and the palatogram against a direct computation, the palatogram on the demo."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tonguevis.analysis.epg import (
    COLUMNS, ELECTRODES, READING, ROWS, epg_indices, epg_layout, palatogram, surface_under, upper_surface,
)


def test_the_reading_palate_has_62_electrodes_the_front_row_six():
    assert READING.sum() == 62 and READING[0].sum() == 6 and not READING[0, 0] and not READING[0, 7]
    assert len(ELECTRODES) == 62 and ELECTRODES[0] == "r1c2" and ELECTRODES[5] == "r1c7" and ELECTRODES[-1] == "r8c8"


def _direct_indices(page: np.ndarray) -> tuple[float, float, float, float]:
    """The indices of one palatogram, written out from the papers (percent, CoG, Fontdevila AI, its mirror)."""
    counts = [int(page[r].sum()) for r in range(ROWS)]
    total = sum(counts)
    percent = 100.0 * total / 62
    cog = sum((7.5 - r) * counts[r] for r in range(ROWS)) / total if total else math.nan
    share = [counts[0] / 6] + [counts[r] / 8 for r in range(1, ROWS)]
    ai = math.log(1 * share[4] + 9 * share[3] + 81 * share[2] + 729 * share[1] + 4921 * share[0] + 1) / math.log(5742)
    pi = math.log(1 * share[3] + 9 * share[4] + 81 * share[5] + 729 * share[6] + 4921 * share[7] + 1) / math.log(5742)
    return percent, cog, ai, pi


def test_the_indices_equal_the_definitions_written_out():
    rng = np.random.default_rng(7)
    pages = (rng.random((40, ROWS, COLUMNS)) < rng.random((40, 1, 1))) & READING
    pages[0] = False
    pages[1] = READING
    got = epg_indices(pages)
    for f, page in enumerate(pages):
        want = _direct_indices(page)
        for name, value in zip(("percent_contact", "cog", "anteriority", "posteriority"), want):
            if math.isnan(value):
                assert math.isnan(got[name][f]), name
            else:
                assert got[name][f] == pytest.approx(value, abs=1e-12), (name, f)
    # the landmarks of the scales
    assert got["percent_contact"][0] == 0 and math.isnan(got["cog"][0]) and got["anteriority"][0] == 0
    assert got["percent_contact"][1] == 100 and got["anteriority"][1] == pytest.approx(1.0)
    assert got["posteriority"][1] == pytest.approx(1.0)
    front, back = np.zeros((ROWS, COLUMNS), bool), np.zeros((ROWS, COLUMNS), bool)
    front[0], back[7] = READING[0], READING[7]
    assert epg_indices(front)["cog"][0] == 7.5 and epg_indices(back)["cog"][0] == 0.5
    assert epg_indices(back)["anteriority"][0] == 0 and epg_indices(front)["posteriority"][0] == 0


def test_the_electrodes_lie_on_the_palate_front_to_back_left_to_right():
    from tonguevis.palate import generic_palate
    from tonguevis.sim.palate_regions import palate_frame

    palate = generic_palate()
    layout = epg_layout(palate)
    used = layout.used
    assert np.array_equal(used, READING)
    points = layout.positions[used]
    gap, _ = palate.clearance(points)
    assert np.all(np.abs(gap) < 1e-9)  # on the surface
    frame = palate_frame(palate)
    row_x = np.nanmean(layout.positions[:, :, 0], axis=1)
    assert np.all(np.diff(row_x) < 0)  # row 1 in front
    assert row_x[0] <= frame.front and row_x[-1] >= frame.front - frame.length
    assert np.all(np.diff(layout.positions[1:, :, 1], axis=1) < 0)  # column 1 on the left (+y)


def _bumpy_surface(n: int = 9):
    """A triangulated height field z = f(x, y) on a grid, and f."""
    def f(x, y):
        return 0.01 + 0.2 * x ** 2 - 0.1 * x * y + 0.05 * y

    xs, ys = np.meshgrid(np.linspace(-0.02, 0.02, n), np.linspace(-0.015, 0.015, n))
    points = np.column_stack([xs.ravel(), ys.ravel(), f(xs.ravel(), ys.ravel())])
    tris = []
    for i in range(n - 1):
        for j in range(n - 1):
            a, b, c, d = i * n + j, i * n + j + 1, (i + 1) * n + j, (i + 1) * n + j + 1
            tris += [(a, b, d), (a, d, c)]
    return points, np.array(tris), f


def _direct_under(points, triangles, place):
    """Brute force: every triangle, barycentric coordinates by a linear solve, the highest."""
    best = -np.inf
    for tri in triangles:
        a, b, c = points[tri]
        m = np.array([[b[0] - a[0], c[0] - a[0]], [b[1] - a[1], c[1] - a[1]]])
        s, t = np.linalg.solve(m, place - a[:2])
        if s >= -1e-9 and t >= -1e-9 and s + t <= 1 + 1e-9:
            best = max(best, a[2] + s * (b[2] - a[2]) + t * (c[2] - a[2]))
    return best if np.isfinite(best) else np.nan


def test_the_surface_under_a_place_is_the_highest_triangle_there():
    points, triangles, f = _bumpy_surface()
    # a second, lower sheet under the first: the upper one is found
    lower = points - [0.0, 0.0, 0.005]
    both = np.vstack([points, lower])
    tris = np.vstack([triangles, triangles + len(points)])
    rng = np.random.default_rng(3)
    places = np.column_stack([rng.uniform(-0.025, 0.025, 60), rng.uniform(-0.02, 0.02, 60)])
    frames = np.stack([both, both + [0.001, -0.002, 0.003]])
    got = surface_under(frames, tris, places)
    for k, frame in enumerate(frames):
        for e, place in enumerate(places):
            want = _direct_under(frame, tris, place)
            if np.isnan(want):
                assert np.isnan(got[k, e, 2])
            else:
                assert got[k, e, 2] == pytest.approx(want, abs=1e-12)
    inside = np.isfinite(got[0, :, 2])
    assert 10 < inside.sum() < 60  # some places off the surface, NaN
    # on the grid's flat triangles the height is within the surface's curvature of f
    assert np.allclose(got[0, inside, 2], f(places[inside, 0], places[inside, 1]), atol=2e-5)
    # the candidates restrict the triangles looked at
    none = surface_under(frames, tris, places, np.zeros((2, len(tris)), bool))
    assert np.all(np.isnan(none[..., 2]))


@pytest.fixture(scope="module")
def pressed():
    """The demo /ta/ against the generic palate: the tip pressed on it at each /t/ closure."""
    from tonguevis.io import read_recording
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import simulate

    return simulate(read_recording(DATA_DIR / "spk1_ta.tsv"), modes=60, palate="generic")


def _direct_palatogram(motion, f, layout, nodes, triangles):
    """One frame's 62 contacts by brute force: the surface under each electrode over every triangle, and every
    node tested against every electrode's cell."""
    from tonguevis.analysis.epg import ELECTRODE_TOUCH

    amount = None if motion.velum_lift is None else motion.velum_lift[f:f + 1]
    points = motion.model.mesh.points[nodes] + motion.displacement(f)[nodes] + motion.jaw_offset[f]
    node_gap = motion.palate.clearance(points, lift=None if amount is None else np.repeat(amount, len(points)))[0]
    step = layout.frame.length / ROWS
    want = np.zeros((ROWS, COLUMNS), bool)
    for r in range(ROWS):
        for c in range(COLUMNS):
            if not READING[r, c]:
                continue
            place = layout.positions[r, c, :2]
            z = _direct_under(points, triangles, place)
            if np.isfinite(z):
                gap = motion.palate.clearance(np.array([[place[0], place[1], z]]), lift=amount)[0][0]
                want[r, c] |= gap < ELECTRODE_TOUCH
            ys = layout.positions[r, :, 1]
            half = 0.5 * abs(np.diff(ys[np.isfinite(ys)])[0])
            top, bottom = layout.frame.front - r * step, layout.frame.front - (r + 1) * step
            for p, gap in zip(points, node_gap):
                if gap < ELECTRODE_TOUCH and bottom < p[0] <= top and abs(p[1] - place[1]) <= half:
                    want[r, c] = True
    return want


def test_the_palatogram_equals_a_direct_computation(pressed):
    """Every 60th frame and every other closure: each electrode lit exactly as the brute force says."""
    motion = pressed
    closures = motion.metadata["contact"]["closures"]["maximum_constriction_frames"]
    frames = np.unique(np.r_[np.arange(0, motion.n_frames, 60), closures[::2]])
    gram = palatogram(motion, frames)
    nodes, triangles = upper_surface(motion.model)
    lit_somewhere = 0
    for k, f in enumerate(frames):
        want = _direct_palatogram(motion, f, gram.layout, nodes, triangles)
        assert np.array_equal(gram.contacts[k], want), f
        lit_somewhere += want.any()
    assert lit_somewhere >= 10  # the test saw contacts, not only empty palatograms
    assert np.array_equal(gram.times, motion.times[frames])
    at_closures = gram.contacts[np.isin(frames, closures)]
    assert at_closures.any(axis=(1, 2)).mean() >= 0.8  # the tip on the palate at the /t/ closures
    assert np.all(~gram.contacts[:, ~READING])


def test_a_stop_lights_electrodes_at_its_closure_and_the_csv_says_so(pressed, tmp_path):
    from tonguevis.analysis.epg import production_epg, table_columns
    from tonguevis.preprocess.gesture_table import write_rows
    from tonguevis.workflows.recording import find_recording_productions
    from tonguevis.io import read_recording
    from tonguevis.paths import DATA_DIR

    table = find_recording_productions(read_recording(DATA_DIR / "spk1_ta.tsv"), keep=None)
    epg = production_epg(pressed, table)
    assert len(epg) == len(table) >= 20
    touching = [e for e in epg if e["epg_percent_contact"] > 0]
    assert len(touching) >= 0.8 * len(epg)
    # the closure's palatogram is the fullest within 30 ms of the closure
    e, production = epg[0], table[0]
    around = np.flatnonzero(np.abs(pressed.times - production.closure) <= 0.03 + 1e-9)
    fullest = palatogram(pressed, around).indices()["percent_contact"].max()
    assert e["epg_percent_contact"] == pytest.approx(fullest)
    gram = palatogram(pressed, np.arange(0, 200))
    out = write_rows(gram.rows(), table_columns(), tmp_path / "epg.csv")
    lines = out.read_text().splitlines()
    header = lines[0].split(",")
    assert header[0] == "time_s" and header[1:63] == list(ELECTRODES) and header[-1] == "posteriority"
    assert len(lines) == 201
