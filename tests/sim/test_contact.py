"""Tongue-palate contact: the QP against a generic solver, a bar pushed into a plane, palates fitted to traces."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file
from tests.sim._models import bar_model, sensor_rows
from tonguevis.palate import PalateSurface, fit_palate
from tonguevis.sim.contact import correct_frames, penetration, solve_contact

HEIGHT = 0.02


def plane(z: float, tilt: float = 0.0, ridge: float = 0.0) -> PalateSurface:
    """A flat 'palate' z = z0 + tilt·x over the bar (model frame), with a ridge hanging ``ridge`` lower at x = 9 cm."""
    x = np.arange(-0.01, 0.14, 0.001)
    y = np.arange(-0.01, 0.03, 0.002)
    gx, _ = np.meshgrid(x, y)
    return PalateSurface(x, y, z + tilt * gx - ridge * np.exp(-(((gx - 0.09) / 0.01) ** 2)), metadata={"frame": "model"})


@pytest.fixture(scope="module")
def bar():
    model = bar_model(sensors=("TT", "TD"))
    nodes = np.array([model.landmarks.sensors[s] for s in ("TT", "TD")])
    lam, phi_s, _ = sensor_rows(model, nodes, 16)
    top = np.flatnonzero(model.mesh.points[:, 2] > HEIGHT - 1e-9)
    basis = model.basis(16, cache=False)
    dofs = (3 * top[:, None] + np.arange(3)).ravel()
    return model, nodes, lam, phi_s, top, basis.phi[dofs].reshape(len(top), 3, -1)


def test_the_plane_gives_the_right_clearance_and_normal():
    surface = plane(0.03, tilt=0.1)
    gap, normal = surface.clearance(np.array([[0.05, 0.01, 0.03], [0.05, 0.01, 0.04]]))
    cos = 1 / np.sqrt(1 + 0.1**2)
    np.testing.assert_allclose(gap, [0.005 * cos, -0.005 * cos], atol=1e-12)
    np.testing.assert_allclose(normal[0], [0.1 * cos, 0.0, -cos], atol=1e-12)  # down, away from the palate
    moved = surface.transformed(np.eye(3), 2.0, np.array([0.0, 0.0, 0.01]))
    g2, _ = moved.clearance(np.array([[0.1, 0.02, 0.07]]))  # own point (0.05, 0.01, 0.03) mapped
    np.testing.assert_allclose(g2, 2 * gap[:1], atol=1e-12)


def test_contact_solution_equals_a_generic_constrained_solver(bar):
    """The active-set / NNLS solve against SciPy's SLSQP on the same QP (linearised plane: exact)."""
    from scipy.optimize import minimize

    from tonguevis.sim.contact import _active_set

    model, nodes, lam, phi_s, top, phi_top = bar
    roof = plane(HEIGHT + 0.004)
    target = np.array([0.0, 0.0, 0.010, 0.0, 0.0, 0.0])  # the tip pulled 10 mm up, 6 mm beyond the roof
    P = phi_s.reshape(6, -1)
    gram = (P / lam) @ P.T
    comp = np.full(6, 1e-3)
    q0 = P.T @ np.linalg.solve(gram + 1e-3 * np.eye(6), target) / lam
    pts = model.mesh.points
    q, lam_c, rows = _active_set(lam, P, gram, phi_top, pts[top], roof, np.zeros(3), target, comp,
                                 np.ones(6, bool), q0, np.ones(len(top), bool), 0.0)
    A = phi_top[:, 2, :]  # the plane is flat: the clearance row is the vertical displacement
    gap0 = HEIGHT + 0.004 - pts[top, 2]
    objective = lambda q: 0.5 * q @ (lam * q) + 0.5 * np.sum((P @ q - target) ** 2) / 1e-3  # noqa: E731
    ref = minimize(objective, np.zeros(len(lam)), jac=lambda q: lam * q + P.T @ (P @ q - target) / 1e-3,
                   constraints=[{"type": "ineq", "fun": lambda q: gap0 - A @ q, "jac": lambda q: -A}],
                   method="SLSQP", options={"ftol": 1e-15, "maxiter": 1000})
    np.testing.assert_allclose(P @ q, P @ ref.x, atol=2e-7)
    np.testing.assert_allclose(A @ q, A @ ref.x, atol=2e-7)
    assert len(lam_c) > 0 and np.all(lam_c > 0) and np.all(A @ q <= gap0 + 1e-9)
    # Complementarity: the pushing nodes are exactly on the roof.
    np.testing.assert_allclose(-rows @ q, (-rows @ q)[0], atol=1e-9)


def test_a_sensor_above_the_palate_wins_and_is_reported():
    model = bar_model(nx=36, sensors=("TT", "TD"))  # nodes every 3.3 mm, as on a tongue
    nodes = np.array([model.landmarks.sensors[s] for s in ("TT", "TD")])
    lam, phi_s, _ = sensor_rows(model, nodes, 60)
    top = np.flatnonzero(model.mesh.points[:, 2] > HEIGHT - 1e-9)
    dofs = (3 * top[:, None] + np.arange(3)).ravel()
    phi_top = model.basis(60, cache=False).phi[dofs].reshape(len(top), 3, -1)
    roof = plane(HEIGHT + 0.004)
    targets = np.zeros((3, 2, 3))
    targets[1, 0, 2] = 0.010  # frame 1: the tip sensor itself 6 mm above the roof
    res = solve_contact(lam, phi_top, phi_s, targets, np.zeros((3, 2)), model.mesh.points, nodes, top, roof,
                        np.zeros((3, 3)))  # hard sensors: the tip must reach its target
    assert res["conflicts"] == [(1, 0)]
    assert res["targets"][1, 0, 2] == pytest.approx(0.010)  # followed through the roof: the sensor wins
    # ... and only its neighbourhood goes with it: the rest of the bar is held below the roof.
    q = _static_shapes(lam, phi_s.reshape(6, -1), res, targets)[1]
    z = model.mesh.points[top, 2] + np.einsum("kcm,m->kc", phi_top, q)[:, 2]
    far = np.linalg.norm(model.mesh.points[top] - model.mesh.points[nodes[0]], axis=1) > 0.012
    assert z[~far].max() > HEIGHT + 0.004 and z[far].max() <= HEIGHT + 0.004 + 1e-9
    assert res["targets"][0, 0, 2] == 0.0
    # Frame 1's held bar presses on the roof (3 nodes); the frames without a target touch nothing.
    assert res["active"][0] == res["active"][2] == 0 and res["active"][1] > 0


def test_a_bar_pulled_into_a_plane_stays_below_it_and_touches_it(bar):
    model, nodes, lam, phi_s, top, phi_top = bar
    roof = plane(HEIGHT + 0.004, ridge=0.003)  # 4 mm above the bar, a ridge down to 1 mm at x = 9 cm
    t = np.arange(100) / 100.0
    targets = np.zeros((100, 2, 3))
    targets[:, :, 2] = 0.003 * np.sin(np.pi * t)[:, None] ** 2  # middle (6 cm) and tip (12 cm) rise 3 mm: under
    # the roof themselves, but the bar between them meets the ridge
    comp = np.full((100, 2), 1e-3)
    res = solve_contact(lam, phi_top, phi_s, targets, comp, model.mesh.points, nodes, top, roof, np.zeros((100, 3)))
    P = phi_s.reshape(6, -1)
    q_free = ((np.linalg.solve((P / lam) @ P.T + 1e-3 * np.eye(6), targets.reshape(100, 6).T)).T @ P) / lam
    free = penetration(np.einsum("kcm,fm->fkc", phi_top, q_free), model.mesh.points[top], np.arange(len(top)),
                       roof, np.zeros((100, 3)))
    assert free.max() > 1.5e-3  # without contact the bar would go 1.5+ mm into the ridge
    # With contact: every frame's static shape is below the roof (to the margin), and some frames touch it.
    q_c = _static_shapes(lam, P, res, targets)
    u = np.einsum("kcm,fm->fkc", phi_top, q_c)
    pen = penetration(u, model.mesh.points[top], np.arange(len(top)), roof, np.zeros((100, 3)))
    assert pen.max() < 1e-9 and np.count_nonzero(res["active"]) > 20
    # The dynamic shapes, corrected frame by frame, keep out too.
    corrected, frames = correct_frames(lam, phi_top, phi_s, q_free, model.mesh.points, top, roof, np.zeros((100, 3)))
    pen2 = penetration(np.einsum("kcm,fm->fkc", phi_top, corrected), model.mesh.points[top], np.arange(len(top)),
                       roof, np.zeros((100, 3)))
    assert len(frames) > 0 and pen2.max() < 1e-9
    np.testing.assert_allclose(P @ corrected[frames[0]], P @ q_free[frames[0]], atol=1e-12)  # sensors unmoved


def _static_shapes(lam, P, res, targets):
    """q of each frame from the solve's sensor positions and contact forces (static balance)."""
    gram = (P / lam) @ P.T
    c = res["targets"].reshape(len(targets), -1)
    mu = np.linalg.solve(gram, (c - (res["external"] / lam) @ P.T).T).T
    return (mu @ P + res["external"]) / lam


def test_a_palate_fitted_to_a_one_sided_noisy_trace_is_the_dome_mirrored():
    rng = np.random.default_rng(0)
    dome = lambda x, y: 0.012 - 40 * (x - 0.02) ** 2 - 60 * y**2  # noqa: E731 - metres, midline y = 0
    x = rng.uniform(0.0, 0.04, 1500)
    y = rng.uniform(0.0, 0.015, 1500)  # the left side only
    z = dome(x, y) + rng.normal(0, 2e-4, len(x))
    z[:40] += 0.01  # the probe leaving the mouth
    surface = fit_palate(np.column_stack([x, y, z]), midline_y=0.0)
    assert surface.metadata["kept"] <= 1500 - 40 and surface.metadata["rms_m"] < 4e-4
    probe = np.array([[0.02, -0.01, 0.0], [0.03, 0.008, 0.0], [0.01, -0.012, 0.0]])  # right side: mirrored
    gap, _ = surface.clearance(probe)
    slope = np.hypot(-80 * (probe[:, 0] - 0.02), -120 * probe[:, 1])  # the clearance is slope-corrected
    np.testing.assert_allclose(gap, dome(probe[:, 0], probe[:, 1]) / np.sqrt(1 + slope**2), atol=3e-4)
    far, _ = surface.clearance(np.array([[0.09, 0.0, 0.0]]))
    assert np.isnan(far[0])  # never extrapolated beyond the traced footprint


def test_palate_files_round_trip(tmp_path):
    surface = plane(0.03, tilt=0.05).transformed(np.eye(3), 1.0, np.array([0.0, 0.0, 0.002]))
    surface.save(tmp_path / "palate.stl")
    back = PalateSurface.load(tmp_path / "palate.stl")
    pts = np.array([[0.05, 0.01, 0.02], [0.1, 0.0, 0.03]])
    np.testing.assert_allclose(back.clearance(pts)[0], surface.clearance(pts)[0])
    (tmp_path / "palate.palate.npz").unlink()  # the mesh alone: sampled from below
    mesh_only = PalateSurface.load(tmp_path / "palate.stl")
    np.testing.assert_allclose(mesh_only.clearance(pts)[0], surface.clearance(pts)[0], atol=2e-4)


def test_a_palate_file_that_is_not_a_mesh_format_is_refused_before_the_fit(tmp_path, capsys):
    """`--out palate.npz` used to end in meshio's traceback after the whole fit; now the command
    stops at once (the traces are not even read: this one does not exist) with one line naming
    the file, and save() refuses it too, writing nothing."""
    from tonguevis.cli import main
    from tonguevis.palate import PalateError

    out = tmp_path / "palate.npz"
    assert main(["palate", str(tmp_path / "missing_trace.tsv"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(out) in err[0] and ".npz is not a surface mesh format" in err[0]
    with pytest.raises(PalateError, match="no extension"):
        plane(0.01).save(tmp_path / "palate")
    assert list(tmp_path.iterdir()) == []


def test_the_speakers_palate_from_the_real_traces():
    from tonguevis.io import read_recording
    from tonguevis.palate import midline_of, trace_points

    files = ["002_OSN12_Palate_MidSagital_HR.tsv", "003_OSN12_Palate_Coronal_HR.tsv", "004_OSN12_Palate_Scribble_HR.tsv"]
    recs = [read_recording(shared_file("ema", "optispeech", f)) for f in files]
    pts = np.concatenate([trace_points(r) for r in recs])
    surface = fit_palate(pts, midline_y=float(np.mean([midline_of(r) for r in recs])))
    assert surface.metadata["rms_m"] < 1.5e-3 and surface.metadata["kept"] > 0.8 * len(pts)
    # A vault: the midline rises from the alveolar ridge (front) to the hard palate behind it.
    y0 = surface.metadata["midline_y"]
    front, _ = surface.clearance(np.array([[0.008, y0, -0.1]]))
    back, _ = surface.clearance(np.array([[-0.012, y0, -0.1]]))
    assert back[0] > front[0] + 0.003


def test_simulate_keeps_the_demo_tongue_below_the_generic_palate(capsys):
    """The paper's hard constraints push the demo /ta/ 2 mm into the shipped palate; contact keeps it out."""
    from tonguevis.cli import main
    from tonguevis.io import read_recording
    from tonguevis.palate import generic_palate
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import TongueModel, simulate
    from tonguevis.sim.contact import contact_frames, penetration as deepest
    from tonguevis.preprocess.targets import prepare_targets

    rec = read_recording(DATA_DIR / "spk1_ta.tsv")
    model = TongueModel.default()
    free = simulate(rec, model, sensor_stiffness=None)
    jaw = prepare_targets(rec, model).jaw_offset
    before = deepest(free.displacements(), model.mesh.points, model.dorsal_nodes, generic_palate(), jaw)
    assert before.max() > 1e-3
    held = simulate(rec, model, sensor_stiffness=None, palate="generic")
    assert held.penetration.max() < 5e-4 and held.metadata["contact"]["frames_in_contact"] > 10
    assert held.metadata["contact"]["closures"]["closures"] > 10  # the tip pressed on it at the closures, still out
    assert held.contact_area.max() > 0
    # Every frame where the tongue enters the palate has a contact area: the free motion enters it in
    # 66 frames (counting only the nodes outside it, 10 of them read 0 mm²).
    pen, area = contact_frames(free.displacements(), model.mesh.points, model.dorsal_nodes, generic_palate(), jaw,
                               model.surface_faces)
    assert (pen > 0).sum() > 10 and np.all(area[pen > 0] > 0)
    assert held.metadata["plausibility"]["volume_change_max_percent"] < 2.0
    assert main(["simulate", str(DATA_DIR / "spk1_ta.tsv"), "--palate", "generic", "--sensor-stiffness", "hard",
                 "--quiet"]) == 0
    assert "palate: deepest penetration 0." in capsys.readouterr().out


def test_a_sensor_above_the_palate_is_counted_as_penetration():
    """The palate 4 mm lower than the shipped one: the demo /ta/'s tip sensor goes above it at every
    /t/. The figures say so (the sensor's depth, the frames, the tongue inside around it), and the
    summary line names the sensor, instead of 0.00 mm and no contact."""
    from tonguevis.io import read_recording
    from tonguevis.palate import generic_palate
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import TongueModel, simulate
    from tonguevis.sim.plausibility import contact_line

    low = generic_palate().transformed(np.eye(3), 1.0, np.array([0.0, 0.0, -0.004]))
    low.metadata.update(generic_palate().metadata)  # still the model's frame: used as is
    rec = read_recording(DATA_DIR / "spk1_ta.tsv")
    motion = simulate(rec, TongueModel.default(), modes=40, palate=low)
    c = motion.metadata["contact"]
    tip = c["sensors_above_palate"]["TT"]
    assert tip["frames"] > 20 and tip["deepest_mm"] > 0.5
    # the measured tip, on its node's rest, really is above the lowered palate by that much
    k = motion.sensor_names.index("TT")
    gap, _ = motion.palate.clearance(motion.targets[:, k] + motion.jaw_offset)
    assert np.nanmax(-gap) * 1e3 == pytest.approx(tip["deepest_mm"], rel=1e-6)
    assert np.sum(gap < 0) == tip["frames"]
    assert c["penetration_max_mm"] >= tip["deepest_mm"] and c["frames_in_contact"] >= 20
    assert motion.penetration.max() * 1e3 == pytest.approx(c["tongue_penetration_max_mm"])
    line = contact_line(motion.metadata)
    assert "TT in" in line and f"deepest penetration {c['penetration_max_mm']:.2f} mm" in line
    assert motion.palate is not None  # the placed palate comes with the motion: no second preparation


def test_a_palate_too_low_is_raised_where_the_sensors_go_and_said_once(caplog, tmp_path):
    """A speaker's palate 8 mm too low: simulate() raises it where the sensors went above it (the speech wins
    over the trace there) and says so once, in one line; the views then draw the surface it placed (no second
    preparation, nothing said again), and the summary says how far and where."""
    import logging

    from tonguevis.workflows.simulation import shown_palate
    from tonguevis.io import read_recording
    from tonguevis.palate import fit_palate
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import TongueModel, simulate
    from tonguevis.sim.plausibility import contact_line

    rec = read_recording(DATA_DIR / "spk1_ta.tsv", sensor_map=DATA_DIR / "sensor_map.json")
    tip = rec.sensors["TT"]
    centre = np.nanmean(tip, axis=0)
    xs, ys = np.meshgrid(np.linspace(-0.03, 0.03, 121), np.linspace(-0.02, 0.02, 81))  # traced densely
    roof = np.column_stack([xs.ravel() + centre[0], ys.ravel() + centre[1], np.full(xs.size, np.nanmax(tip[:, 2]))])
    palate = fit_palate(roof - [0.0, 0.0, 0.008])
    path = tmp_path / "low.stl"
    palate.save(path)
    model = TongueModel.default()
    with caplog.at_level(logging.INFO, logger="tonguevis"):
        motion = simulate(rec, model, modes=40, palate=path)
        shown = shown_palate(rec, motion, model, path)
    said = [r for r in caplog.records if r.getMessage().startswith("palate: traced part kept")]
    assert len(said) == 1 and "raised where the sensors went above it: up to" in said[0].getMessage()
    info = motion.metadata["contact"]["palate"]["speaker_palate"]
    assert 7.0 < info["traced_raised_mm"] < 9.5  # 8 mm and the coil's half, where the tip went highest
    assert shown.surface is motion.palate and shown.raised_mm == pytest.approx(info["traced_raised_mm"])
    line = contact_line(motion.metadata)
    assert f"raised up to {info['traced_raised_mm']:.1f} mm" in line and "where the sensors went above it" in line
    # the palate is under no sensor: each sensor's node, where measured, is below the surface simulated against
    lift = np.zeros(motion.n_frames) if motion.velum_lift is None else motion.velum_lift
    sensors = motion.targets + motion.jaw_offset[:, None]
    gap = motion.palate.clearance(sensors.reshape(-1, 3), lift=np.repeat(lift, sensors.shape[1]))[0]
    assert np.nanmin(gap) > -0.5e-3


def test_a_fitted_palate_has_no_fold_and_says_its_bound():
    """Noisy traces (0.3 mm jitter) of a vault: the fit is smoothed until it bends nowhere tighter than
    3 mm, and says the bound and the tightest bend reached; the plain fit folds."""
    from tonguevis.palate import MIN_BEND_RADIUS, bend_curvature

    rng = np.random.default_rng(4)
    xy = rng.uniform([-0.02, -0.015], [0.02, 0.015], (1500, 2))
    z = 0.01 - 40 * xy[:, 1] ** 2 - 5 * xy[:, 0] ** 2 + rng.normal(0, 3e-4, len(xy))  # radii 12.5 and 100 mm
    points = np.column_stack([xy, z])
    plain = fit_palate(points, midline_y=0.0, min_radius=None)
    bounded = fit_palate(points, midline_y=0.0)
    assert 1.0 / bend_curvature(np.asarray(plain.z), 1e-3) < MIN_BEND_RADIUS  # the jitter folds the plain fit
    reached = bounded.metadata["bend_radius_m"]
    assert reached >= MIN_BEND_RADIUS and bounded.metadata["min_bend_radius_m"] == MIN_BEND_RADIUS
    assert reached == pytest.approx(1.0 / bend_curvature(np.asarray(bounded.z), 1e-3))
    assert bounded.metadata["rms_m"] < 1e-3  # still on the traces


def test_the_bend_is_the_surface_s_own_where_it_is_steep():
    """A cylinder of radius 5 mm about the x axis, its height field sampled up to slope 2.3: every cell bends
    with radius 5 mm (the height field's Hessian says 1 / (5 mm x (1 + slope²)^1.5), 0.4 mm at the steepest)."""
    from tonguevis.palate import bend_curvature

    step, radius = 1e-4, 5e-3
    y = np.arange(-4.6e-3, 4.6e-3 + step / 2, step)
    z = np.sqrt(radius ** 2 - y ** 2)[:, None] * np.ones((1, 12))
    assert bend_curvature(z, step) == pytest.approx(1.0 / radius, rel=0.02)


def test_a_traced_palate_is_joined_to_the_generic_one_behind_it():
    """A palate traced over the front only: placed for a simulation it becomes a whole roof, the
    traced part where it was traced, the generic palate (moved to meet it) behind and beside it,
    continuous across the seam."""
    from tonguevis.palate import SEAM, generic_palate, joined_palate

    generic = generic_palate()
    gx, gy = np.meshgrid(generic.x, generic.y)
    front = np.isfinite(generic.z) & (gx > np.nanpercentile(gx[np.isfinite(generic.z)], 60))
    traced = PalateSurface(generic.x, generic.y, np.where(front, generic.z + 0.002, np.nan))  # 2 mm higher
    whole = joined_palate(traced, generic)
    assert whole.metadata["joined"]["generic_shift_mm"] == pytest.approx(2.0, abs=0.05)
    # a point behind the traced part now has a roof 2 mm above the generic one
    back = np.array([[float(np.nanpercentile(gx[np.isfinite(generic.z)], 20)), 0.0, -0.05]])
    assert np.isnan(traced.clearance(back)[0][0])
    assert whole.clearance(back)[0][0] == pytest.approx(generic.clearance(back)[0][0] + 0.002, abs=2e-4)
    # no step at the seam: neighbouring cells differ by no more than the roof's own slope allows
    z = np.asarray(whole.z)
    steps = np.abs(np.diff(z, axis=1))
    assert np.nanmax(steps) < 3e-3 and SEAM > 0


def test_the_height_field_of_triangles_equals_a_plain_reference():
    """The box-indexed rasterisation (palate._height_field) against every grid point tested against
    every triangle: the lowest triangle over each point, NaN where none is."""
    from tonguevis.palate import _height_field

    rng = np.random.default_rng(7)
    gx, gy = np.meshgrid(np.linspace(0, 0.02, 9), np.linspace(0, 0.015, 7))
    pts = np.column_stack([gx.ravel(), gy.ravel(), 0.01 + 0.002 * rng.random(gx.size)])
    pts[:, :2] += rng.normal(0, 3e-4, (gx.size, 2))
    ids = np.arange(gx.size).reshape(gx.shape)
    quads = np.stack([ids[:-1, :-1], ids[:-1, 1:], ids[1:, 1:], ids[1:, :-1]], axis=-1).reshape(-1, 4)
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    tris = np.concatenate([tris, tris[:5] + 0])  # a fold: the same triangles lifted below stay the lowest
    pts = np.concatenate([pts, pts[tris[:5].ravel()] - [0, 0, 0.003]])
    tris[-5:] = len(pts) - 15 + np.arange(15).reshape(5, 3)
    fast = _height_field(pts, tris, 1e-3, {})
    xs, ys = np.meshgrid(fast.x, fast.y)
    expected = np.full(xs.shape, np.nan)
    for (j, i), px in np.ndenumerate(xs):
        p = np.array([px, ys[j, i]])
        for t in tris:
            a, b, c = pts[t]
            m = np.array([b[:2] - a[:2], c[:2] - a[:2]]).T
            if abs(np.linalg.det(m)) < 1e-18:
                continue
            u, v = np.linalg.solve(m, p - a[:2])
            if u >= -1e-9 and v >= -1e-9 and u + v <= 1 + 1e-9:
                h = a[2] + u * (b[2] - a[2]) + v * (c[2] - a[2])
                expected[j, i] = h if np.isnan(expected[j, i]) else min(expected[j, i], h)
    np.testing.assert_allclose(fast.z, expected, atol=1e-12, equal_nan=True)


def test_a_traced_palate_shaped_unlike_the_generic_one_joins_without_a_cliff():
    """Real traces differ from the generic roof in shape, not only in height (up to 10 mm along the
    edge): the generic roof is bent to meet the traced edge, the traced heights kept inside."""
    from tonguevis.palate import SEAM, generic_palate, joined_palate

    generic = generic_palate()
    gx, gy = np.meshgrid(generic.x, generic.y)
    defined = np.isfinite(generic.z)
    front = defined & (gx > np.nanpercentile(gx[defined], 60))
    tilt = 0.25 * (gy - float(np.mean(gy[front])))  # the traced roof tilted sideways: +-4 mm at its edges
    traced = PalateSurface(generic.x, generic.y, np.where(front, generic.z + 0.002 + tilt, np.nan))
    plain_steps = np.nanmax(np.abs(np.diff(np.asarray(generic.z), axis=0)))
    whole = joined_palate(traced, generic)
    z = np.asarray(whole.z)
    steps = max(np.nanmax(np.abs(np.diff(z, axis=0))), np.nanmax(np.abs(np.diff(z, axis=1))))
    assert steps < plain_steps + 1e-3  # no cliff: at most the generic roof's own slope and 1 mm per mm
    # deep inside the traced part its own heights
    from scipy.ndimage import binary_erosion

    deep = binary_erosion(front, iterations=int(np.ceil(SEAM / 1e-3)) + 1)
    grid_x = np.searchsorted(whole.x, gx[deep]); grid_y = np.searchsorted(whole.y, gy[deep])
    np.testing.assert_allclose(z[grid_y, grid_x], (generic.z + 0.002 + tilt)[deep], atol=1e-6)
