"""The speaker's palate as the tongue meets it (issue 36): traced where traced, raised only where the speech's
sensors go above it, estimated from the speech behind and beside it, a velum that lifts frame by frame."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.palate import MIN_SUPPORT, PalateSurface, fit_palate
from tonguevis.sim.speaker_palate import COIL_HALF, MIN_VELUM_SHARE, speaker_palate, velum_lift


def _vault(step: float = 0.7e-3, back: float = -0.03) -> np.ndarray:
    """Dense trace points (m) of a gentle vault from x = back to x = 0.02 (a probe drawn over it)."""
    xs, ys = np.meshgrid(np.arange(back, 0.02 + step / 2, step), np.arange(-0.015, 0.015 + step / 2, step))
    z = 0.02 - 200.0 * ys ** 2 - 2.0 * (xs + 0.005) ** 2
    return np.column_stack([xs.ravel(), ys.ravel(), z.ravel()])


def _generic_roof() -> PalateSurface:
    x = np.arange(-0.07, 0.03, 1e-3)
    y = np.arange(-0.025, 0.025 + 5e-4, 1e-3)
    z = 0.02 - 200.0 * y[:, None] ** 2 - 2.0 * (x[None, :] + 0.005) ** 2 - 0.0 * x[None, :]
    return PalateSurface(x, y, z, metadata={"frame": "model"})


def test_support_counts_where_the_probe_went_not_its_mirror_image():
    """A palate traced on its left half only: the fit mirrors it (the right half is the fit's estimate) but the
    right half has no support, so it is not 'traced'."""
    points = _vault()
    left = points[points[:, 1] >= 0.002]
    surface = fit_palate(left, midline_y=0.0)
    gx, gy = np.meshgrid(surface.x, surface.y)
    defined = np.isfinite(surface.z)
    assert defined[gy < -0.006].any()  # the mirror image made the right side
    traced = defined & (surface.support >= MIN_SUPPORT)
    assert traced[(gy > 0.006) & defined].mean() > 0.5 and not traced[(gy < -0.006) & defined].any()


def test_traced_kept_where_no_sensor_goes_above_and_raised_only_where_one_does():
    traced = fit_palate(_vault(), midline_y=0.0)
    frames = 50
    sensors = np.full((frames, 2, 3), np.nan)
    sensors[:, 0] = [0.0, 0.0, 0.0]  # far below the front: nothing to raise there
    sensors[:, 1] = [-0.02, 0.0, 0.0]
    sensors[10, 1, 2] = 0.02 + 0.003  # once, 3 mm above where the vault is at x = -20 mm (there z ~ 19.5 mm)
    sensors[11, 1, 2] = 0.02 + 0.003
    surface, lift, info = speaker_palate(traced, None, sensors)
    front = np.array([[0.01, 0.0, 0.0]])
    assert surface.clearance(front)[0][0] == pytest.approx(traced.clearance(front)[0][0], abs=1e-9)
    gap = surface.clearance(sensors[10:12, 1])[0]
    assert np.all(gap >= COIL_HALF * 0.95)  # the sensor the coil's half below the palate, not above it
    assert info["traced_raised_mm"] == pytest.approx(1e3 * (0.023 + COIL_HALF - traced._interp(
        traced._to_own(sensors[10:11, 1])[:, :2])[0][0]), abs=0.5)  # the most any cell rose (they curve away)
    assert -22 < info["traced_raised_at_mm"][0] < -18 and info["traced_raised_share"] < 0.2
    assert lift.shape == (frames,) and not lift.any()  # no velum: all traced, nothing behind it


def test_the_estimated_roof_is_raised_broadly_and_the_traced_palate_narrowly():
    """A sensor 3 mm above the generic roof beside the traced vault (y = -20 mm, no trace there) raises the
    estimated roof as a broad roof (cells 8 mm from it by over half the need: no groove along the sensor's
    path, the cause of the /k/ cone), while traced cells beyond RAISE_REACH of it stay where they were traced."""
    from tonguevis.sim.speaker_palate import ESTIMATE_RAISE_FLAT, ESTIMATE_RAISE_REACH, RAISE_REACH

    traced = fit_palate(_vault(back=-0.03), midline_y=0.0)
    roof = _generic_roof()
    at = np.array([-0.010, -0.020, 0.0])
    base = roof._interp(roof._to_own(at[None])[:, :2])[0][0]

    def heights(z_sensor, cells):
        sensors = np.tile(at + [0.0, 0.0, z_sensor], (20, 1, 1))
        surface, _, info = speaker_palate(traced, roof, sensors)
        return surface._interp(surface._to_own(cells)[:, :2])[0], info

    estimated = np.array([[-0.010, -0.020, 0.0], [-0.018, -0.020, 0.0], [-0.002, -0.020, 0.0]])
    traced_cells = np.array([[-0.010, -0.0125, 0.0], [-0.019, -0.014, 0.0]])  # 7.5 and 10.8 mm away
    low, _ = heights(base - 0.010, np.vstack([estimated, traced_cells]))
    high, info = heights(base + 0.003, np.vstack([estimated, traced_cells]))
    raised = high - low
    need = base + 0.003 + COIL_HALF - low[0]  # above the roof as joined to the traced edge
    assert need > 0.002 and raised[0] == pytest.approx(need, abs=2e-4)  # met in full at the sensor
    assert ESTIMATE_RAISE_FLAT < 0.008 < ESTIMATE_RAISE_REACH
    assert np.all(raised[1:3] > 0.5 * need)  # 8 mm away, where a 6 mm raise would have left the roof as it was
    assert np.all(np.abs(raised[3:]) < 1e-9) and np.all(np.linalg.norm(traced_cells - at, axis=1) > RAISE_REACH)
    assert np.all(high[:3] <= base + 0.003 + COIL_HALF + 1e-9)  # raised towards the coil's top, never above it
    assert info["estimated_raised_mm"] >= 1e3 * need - 0.2 and info["traced_raised_mm"] < 1e-6


def test_the_velum_behind_the_traced_palate_lifts_for_the_dorsum_frame_by_frame():
    """Traced to x = -30 mm; the generic roof behind; a dorsum sensor at x = -40 mm going 4 mm above the
    roof there in frames 20-29: the velum lifts just enough there (the least lift, to the sensor's coil),
    held two frames either side, and not at all elsewhere; palate_at lifts it as the simulation does."""
    traced = fit_palate(_vault(back=-0.03), midline_y=0.0)
    roof = _generic_roof()
    frames = 60
    sensors = np.full((frames, 1, 3), np.nan)
    at = np.array([-0.040, 0.0, 0.0])
    base_height = roof._interp(roof._to_own(at[None])[:, :2])[0][0]
    sensors[:, 0] = at + [0.0, 0.0, base_height - 0.010]  # well under the roof
    sensors[20:30, 0, 2] = base_height + 0.004
    surface, lift, info = speaker_palate(traced, roof, sensors)
    assert info["hinge_x_mm"] == pytest.approx(-30.0, abs=3.0)
    share = surface._interp(surface._to_own(at[None])[:, :2], surface.lift_shape)[0][0]
    assert share >= MIN_VELUM_SHARE
    lifted = np.flatnonzero(lift > 0)
    assert lifted.min() == 18 and lifted.max() == 31  # frames 20-29, held two frames either side
    gap = np.array([surface.lifted(lift[f]).clearance(sensors[f])[0][0] for f in range(20, 30)])
    assert np.all(gap >= COIL_HALF * 0.99) and np.all(gap <= COIL_HALF * 1.2)  # just enough
    np.testing.assert_allclose(velum_lift(surface, sensors), lift)
    # the velum's lift is what clearance(lift=) adds, point by point, frame by frame
    probe = np.repeat(sensors[:, 0], 1, axis=0)
    np.testing.assert_allclose(surface.clearance(probe, lift=lift)[0],
                               [surface.lifted(lift[f]).clearance(probe[f:f + 1])[0][0] for f in range(frames)])


def test_the_compiled_clearance_lifts_the_velum_as_numpy_does():
    """The warp kernel's clearance with a per-frame lift equals PalateSurface.clearance(lift=) to 1e-12 m."""
    from tonguevis.sim.contact_kernel import clearances

    traced = fit_palate(_vault(back=-0.03), midline_y=0.0)
    frames = 40
    sensors = np.zeros((frames, 1, 3))
    sensors[:, 0] = [-0.04, 0.0, 0.0]
    surface, _, _ = speaker_palate(traced, _generic_roof(), sensors)
    rng = np.random.default_rng(7)
    base = np.column_stack([rng.uniform(-0.06, 0.02, 200), rng.uniform(-0.012, 0.012, 200), np.full(200, 0.01)])
    disp = rng.normal(scale=0.002, size=(frames, 200, 3))
    offsets = np.column_stack([rng.normal(scale=0.001, size=(frames, 3)), rng.uniform(0, 0.005, frames)])
    gap, normal = clearances(surface, base, disp, offsets, normals=True)
    points = base[None] + disp + offsets[:, None, :3]
    ref, ref_normal = surface.clearance(points.reshape(-1, 3), lift=np.repeat(offsets[:, 3], 200))
    np.testing.assert_allclose(gap.ravel(), ref, atol=1e-12)
    np.testing.assert_allclose(normal.reshape(-1, 3), ref_normal, atol=1e-12)
    assert np.isfinite(ref).sum() > 1000 and np.ptp(offsets[:, 3]) > 0.003


def test_a_motion_keeps_its_velum_and_says_where_the_palate_is(tmp_path):
    """The demo /ka/ against the generic palate: rigid (no velum); its palate_at is the palate.  A motion saved
    with a velum's lift loads it back."""
    from tonguevis.io import read_recording
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import Motion, simulate

    motion = simulate(read_recording(DATA_DIR / "spk1_ka.tsv"), modes=30, palate="generic")
    assert motion.velum_lift is None and motion.palate_at(5) is motion.palate
    motion.velum_lift = np.linspace(0.0, 0.003, motion.n_frames)
    motion.save(tmp_path / "m.npz")
    again = Motion.load(tmp_path / "m.npz")
    np.testing.assert_array_equal(again.velum_lift, motion.velum_lift)
