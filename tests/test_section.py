"""The plane section of a triangle surface (the live view's midsagittal outline)."""

import numpy as np

from tonguevis.analysis.section import plane_section


def test_a_cube_cut_in_the_middle_is_a_square():
    from tonguevis.mesh.structured import box_mesh

    mesh = box_mesh(3, 3, 3, size=(0.02, 0.04, 0.01), origin=(0.0, 0.0, 0.0))
    faces = mesh.boundary_faces()
    segments = plane_section(mesh.points, faces, 0.015)  # between two node layers
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1).sum()
    assert np.isclose(length, 2 * (0.02 + 0.01))  # the 20 x 10 mm square's perimeter
    xz = segments.reshape(-1, 2)
    assert np.allclose(xz.min(axis=0), 0.0) and np.allclose(xz.max(axis=0), (0.02, 0.01))
    assert len(plane_section(mesh.points, faces, 0.05)) == 0  # beside the box


def test_the_midlines_closest_approach_is_the_smallest_of_every_frames_distances(capsys):
    """MidlineProfile.closest_approach (what `tonguevis simulate --palate` prints) against the Palate tab's per-frame
    distances taken frame by frame."""
    from tonguevis.analysis.section import MidlineProfile
    from tonguevis.cli import main
    from tonguevis.io import read_recording
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import simulate

    motion = simulate(read_recording(DATA_DIR / "spk1_ta.tsv"), modes=40, palate="generic")
    profile = MidlineProfile(motion.model)
    gap, behind, t = profile.closest_approach(motion)
    per_frame = []
    for f in range(motion.n_frames):
        head = motion.model.mesh.points + motion.displacement(f) + motion.jaw_offset[f]
        per_frame.append(np.nanmin(profile.distances(motion.palate, head)))
    f = int(np.nanargmin(per_frame))
    assert abs(gap - per_frame[f]) < 1e-9
    assert t == motion.times[f] and behind in profile.position_mm
    assert main(["simulate", str(DATA_DIR / "spk1_ta.tsv"), "--modes", "40", "--palate", "generic", "--quiet"]) == 0
    assert f"midline: closest to the palate {gap:.1f} mm, {behind:.0f} mm behind the tip, at {t:.2f} s" in \
        capsys.readouterr().out
