"""find_landmarks and friends on the shipped tongue and on the ArtiSynth tongue."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file
from tonguevis.mesh import (
    ARTISYNTH_AXES,
    ANCHOR_NAMES,
    Landmarks,
    MeshError,
    TetMesh,
    dorsal_surface_nodes,
    find_landmarks,
    inferior_surface_nodes,
    load_default_mesh,
    midline_y,
    read_landmarks,
    read_mesh,
)
from tonguevis.mesh.landmarks import midsagittal_dorsum


@pytest.fixture(scope="module")
def ours():
    return load_default_mesh()


@pytest.fixture(scope="module")
def artisynth():
    return read_mesh(shared_file("artisynth", "tongue3.1.node"), axes=ARTISYNTH_AXES)


def test_artisynth_mesh_facts(artisynth):
    assert artisynth.n_nodes == 1803 and artisynth.n_tets == 8606
    assert artisynth.volume * 1e6 == pytest.approx(97.0, abs=0.05)
    face_file = shared_file("artisynth", "tongue3.1.face")
    assert len(artisynth.boundary_faces()) == int(face_file.read_text().split()[0])
    # our frame: the tip is the most anterior point, some 40 mm above the floor
    tip = artisynth.points[np.argmax(artisynth.points[:, 0])]
    assert 0.035 < tip[2] - artisynth.points[:, 2].min() < 0.05
    assert abs(midline_y(artisynth)) < 5e-4                     # symmetric about raw z = 0


def _check_plausible(mesh: TetMesh, landmarks: Landmarks):
    p = mesh.points
    tip = np.array(landmarks.metadata["tip_m"])
    s = landmarks.sensors
    dorsal = set(dorsal_surface_nodes(mesh).tolist())
    assert set(s.values()) <= dorsal and len(set(s.values())) == len(s)
    tt = np.linalg.norm(p[s["TT"]] - tip)
    assert 0.006 < tt < 0.012                                   # ~10 mm behind the tip
    assert p[s["TT"], 0] > p[s["TB"], 0] > p[s["TD"], 0] > p[s["TBK"], 0]
    assert 0.035 < tip[0] - p[s["TBK"], 0] < 0.05
    y0 = landmarks.metadata["midline_y_m"]
    for name in ("TT", "TB", "TD", "TBK"):
        assert abs(p[s[name], 1] - y0) < 4e-3                   # on the midline, within a node spacing
    assert p[s["TL"], 1] - y0 > 1.5e-3 and p[s["TR"], 1] - y0 < -1.5e-3
    assert abs(p[s["TL"], 0] - p[s["TB"], 0]) < 5e-3            # 2 cm level
    a = p[landmarks.anchors]
    assert len(set(landmarks.anchors.tolist())) == 5
    assert set(landmarks.anchors.tolist()) <= set(inferior_surface_nodes(mesh).tolist())
    sensor_floor = min(p[v, 2] for v in s.values())
    assert np.all(a[:, 2] < sensor_floor - 0.03)                # anchors well below the sensors
    gaps = np.linalg.norm(a[:, None] - a[None], axis=-1)[np.triu_indices(5, 1)]
    assert gaps.min() > 0.005                                   # spread out
    jaw, hyoid = a[:2], a[2:]
    assert jaw[:, 0].min() > hyoid[:, 0].max() + 0.02           # jaw pair in front of the hyoid trio


def test_rule_on_our_mesh(ours):
    _check_plausible(ours, find_landmarks(ours))


def test_rule_on_the_artisynth_mesh(artisynth):
    landmarks = find_landmarks(artisynth)
    _check_plausible(artisynth, landmarks)
    p = artisynth.points
    assert np.linalg.norm(p[landmarks.sensors["TT"]] - p[landmarks.sensors["TD"]]) == pytest.approx(0.02, abs=0.004)


def test_arc_length_targets(ours):
    """The rule's target points sit at the stated arc lengths along the dorsal contour."""
    landmarks = find_landmarks(ours)
    contour = midsagittal_dorsum(ours, landmarks.metadata["midline_y_m"])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(contour, axis=0), axis=1))])
    for name, expected in (("TT", 0.01), ("TB", 0.02), ("TD", 0.03), ("TBK", 0.045)):
        target = np.array(landmarks.metadata["targets_m"][name])
        nearest = np.argmin(np.linalg.norm(contour - target, axis=1))
        assert arc[nearest] == pytest.approx(expected, abs=3e-4)
        assert np.linalg.norm(ours.points[landmarks.sensors[name]] - target) < 4e-3


def test_landmarks_follow_a_moved_mesh(ours):
    """Translating the tongue sideways and up moves the midline; the nodes stay the same."""
    moved = TetMesh(ours.points + [0.003, 0.007, -0.02], ours.tets)
    assert midline_y(moved) == pytest.approx(midline_y(ours) + 0.007, abs=3e-4)
    a, b = find_landmarks(ours), find_landmarks(moved)
    assert a.sensors == b.sensors
    np.testing.assert_array_equal(a.anchors, b.anchors)


def test_lateral_sensors_roughly_mirror(ours):
    landmarks = find_landmarks(ours)
    tl, tr = ours.points[landmarks.sensors["TL"]], ours.points[landmarks.sensors["TR"]]
    assert tl[1] == pytest.approx(-tr[1], abs=3e-3)
    assert tl[0] == pytest.approx(tr[0], abs=4e-3)


def test_overrides(ours):
    landmarks = find_landmarks(ours, overrides={"TT": 5, "anchors": [0, 1, 2, 3, 4], "TM": 7})
    assert landmarks.sensors["TT"] == 5 and landmarks.sensors["TM"] == 7
    np.testing.assert_array_equal(landmarks.anchors, [0, 1, 2, 3, 4])
    with pytest.raises(MeshError, match="5 node ids"):
        find_landmarks(ours, overrides={"anchors": [1, 2]})
    with pytest.raises(MeshError, match="not nodes"):
        find_landmarks(ours, overrides={"TT": ours.n_nodes})


def test_json_round_trip_and_mesh_check(tmp_path, ours, artisynth):
    landmarks = find_landmarks(ours)
    path = tmp_path / "lm.json"
    path.write_text(landmarks.to_json(ours, mesh_file="tongue.vtu"))
    back = read_landmarks(path, ours)
    assert back.sensors == landmarks.sensors
    np.testing.assert_array_equal(back.anchors, landmarks.anchors)
    assert back.metadata["anchor_names"] == list(ANCHOR_NAMES)
    with pytest.raises(MeshError, match="lm.json.*1803-node|lm.json.*-node mesh"):
        read_landmarks(path, artisynth)
    shifted = TetMesh(ours.points + 0.001, ours.tets)
    with pytest.raises(MeshError, match="another mesh"):
        read_landmarks(path, shifted)


@pytest.mark.parametrize("text", ["{", "[]", '{"sensors": {"TT": {}}, "anchors": []}', '{"sensors": 3}'])
def test_malformed_json(tmp_path, text):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(MeshError, match="bad.json"):
        read_landmarks(path)
    with pytest.raises(MeshError, match="cannot read"):
        read_landmarks(tmp_path / "absent.json")


def test_upside_down_mesh_is_not_refused_its_floor_gets_the_sensors(ours):
    """find_landmarks trusts the frame it is given (z up, module docstring): it is not refused.

    A mesh carries no anatomy to tell the dorsum from the floor, and the only
    "is z up?" checks count upward- and downward-facing nodes, which a tongue
    turned over (a half turn about x) has plenty of.  So the rule runs as
    written on the surface now facing up: every sensor lands on the real
    tongue's underside and every anchor on its dorsum.  Orienting the mesh is
    the reader's job (``read_mesh(..., axes=...)``).
    """
    flipped = TetMesh(ours.points * [1, -1, -1], ours.tets)
    landmarks = find_landmarks(flipped)  # no MeshError
    dorsum = set(dorsal_surface_nodes(ours).tolist())
    underside = set(inferior_surface_nodes(ours).tolist())
    assert set(dorsal_surface_nodes(flipped).tolist()) == underside
    assert set(landmarks.sensors) == {"TT", "TB", "TD", "TBK", "TL", "TR"}
    for name, node in landmarks.sensors.items():
        assert node in underside and node not in dorsum, name
    for node in landmarks.anchors.tolist():
        assert node in dorsum and node not in underside
    # the right-side-up mesh is the mirror case: sensors on the dorsum, anchors underneath
    right = find_landmarks(ours)
    assert set(right.sensors.values()) <= dorsum and set(right.anchors.tolist()) <= underside
