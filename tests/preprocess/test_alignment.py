"""Similarity fits recover known transforms; the paper's alignment; midsagittal layouts."""

import numpy as np
import pytest

from tests.preprocess._synthetic import random_rotations
from tonguevis.errors import TonguevisError
from tonguevis.preprocess import SimilarityTransform, align_paper, fit_similarity
from tonguevis.preprocess.alignment import _best_scale, _rotation_between

RHOMBUS = {"TT": [-0.010, 0.0, 0.003], "TD": [-0.030, 0.0, 0.008],
           "TL": [-0.020, 0.006, 0.005], "TR": [-0.020, -0.006, 0.005]}


def known_transform(seed=0, scale=1.37) -> SimilarityTransform:
    rng = np.random.default_rng(seed)
    return SimilarityTransform(scale, random_rotations(rng, 1)[0], rng.normal(0, 0.05, 3))


def test_transform_algebra():
    t = known_transform()
    p = np.random.default_rng(1).normal(size=(7, 3))
    np.testing.assert_allclose(t.inverse().apply(t.apply(p)), p, atol=1e-12)
    homogeneous = np.column_stack([p, np.ones(7)]) @ t.matrix.T
    np.testing.assert_allclose(homogeneous[:, :3], t.apply(p), atol=1e-12)
    u = known_transform(2, 0.8)
    np.testing.assert_allclose((t @ u).apply(p), t.apply(u.apply(p)), atol=1e-12)
    assert t.apply(p[0]).shape == (3,)
    assert t.apply(p.reshape(7, 1, 3)).shape == (7, 1, 3)
    with pytest.raises(TonguevisError, match="proper rotation"):
        SimilarityTransform(1.0, np.diag([1.0, -1.0, 1.0]), np.zeros(3))
    with pytest.raises(TonguevisError, match="positive"):
        SimilarityTransform(0.0, np.eye(3), np.zeros(3))


@pytest.mark.parametrize("seed", range(5))
def test_fit_similarity_recovers_a_known_transform(seed):
    t = known_transform(seed, scale=0.5 + seed * 0.3)
    source = np.array(list(RHOMBUS.values()))  # nearly planar: a reflection would fit too
    fitted = fit_similarity(source, t.apply(source))
    np.testing.assert_allclose(fitted.rotation, t.rotation, atol=1e-9)
    np.testing.assert_allclose(fitted.scale, t.scale, rtol=1e-9)
    np.testing.assert_allclose(fitted.translation, t.translation, atol=1e-10)
    assert np.linalg.det(fitted.rotation) == pytest.approx(1.0)


def test_fit_similarity_is_least_squares_and_never_reflects():
    rng = np.random.default_rng(3)
    source = rng.normal(size=(6, 3))
    mirrored = source * [1, -1, 1]  # the best orthogonal map would be a reflection
    fitted = fit_similarity(source, mirrored)
    assert np.linalg.det(fitted.rotation) == pytest.approx(1.0)
    # a least-squares optimum: no small perturbation of the parameters does better
    cost = lambda tr: np.sum((tr.apply(source) - mirrored) ** 2)  # noqa: E731
    best = cost(fitted)
    for _ in range(20):
        step = SimilarityTransform(1 + rng.normal(0, 1e-3), _small_rotation(rng), rng.normal(0, 1e-3, 3))
        assert cost(step @ fitted) >= best - 1e-12


def _small_rotation(rng, size=1e-3):
    w = rng.normal(0, size, 3)
    kx = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    u, _, vt = np.linalg.svd(np.eye(3) + kx)
    return u @ vt


def test_collinear_sensors_need_the_midsagittal_fit():
    midline = np.array([[-0.01, 0.0, 0.003], [-0.02, 0.0, 0.0062], [-0.035, 0.0, 0.011]])  # 0.1 mm off a line
    with pytest.raises(TonguevisError, match="midsagittal"):
        fit_similarity(midline, midline + 0.01)
    with pytest.raises(TonguevisError, match="shape"):
        fit_similarity(midline, midline[:2])


def test_midsagittal_fit_recovers_a_rotation_about_y():
    angle, scale = 0.3, 1.2
    c, s = np.cos(angle), np.sin(angle)
    rot_y = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    t = SimilarityTransform(scale, rot_y, np.array([0.01, 0.002, -0.03]))
    midline = np.array([[-0.01, 0.0, 0.003], [-0.02, 0.0, 0.006], [-0.035, 0.0, 0.004]])  # TT, TB, TBK
    fitted = fit_similarity(midline, t.apply(midline), midsagittal=True)
    np.testing.assert_allclose(fitted.rotation, rot_y, atol=1e-12)
    assert fitted.scale == pytest.approx(scale)
    np.testing.assert_allclose(fitted.apply(midline), t.apply(midline), atol=1e-12)
    # the rotation never leaves the midsagittal plane, even for off-plane targets
    target = t.apply(midline) + [[0, 0.003, 0], [0, -0.001, 0], [0, 0.004, 0]]
    off = fit_similarity(midline, target, midsagittal=True)
    np.testing.assert_allclose(off.rotation[1], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(off.apply(midline)[:, 1].mean(), target[:, 1].mean(), atol=1e-12)


def test_align_paper_recovers_a_known_transform():
    for seed in range(4):
        t = known_transform(seed, scale=0.7 + 0.2 * seed)
        nodes = {n: t.apply(np.asarray(p)) for n, p in RHOMBUS.items()}
        fitted = align_paper(RHOMBUS, nodes)
        np.testing.assert_allclose(fitted.rotation, t.rotation, atol=1e-9)
        assert fitted.scale == pytest.approx(t.scale, rel=1e-9)
        for n, p in RHOMBUS.items():
            np.testing.assert_allclose(fitted.apply(np.asarray(p)), nodes[n], atol=1e-11)


def _assert_proper_rotation_taking(r, u, v):
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(r @ (u / np.linalg.norm(u)), v / np.linalg.norm(v), atol=1e-12)


@pytest.mark.parametrize("u", [[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, 0, -2.5], [0.9, 0.1, 0.0],
                               [0.95, -0.2, 0.1], [3.0, -1.0, 2.0], [-0.2, 0.7, -0.4]])
def test_rotation_between_opposite_directions_is_a_proper_half_turn(u):
    """u onto -u: no smallest rotation exists, so the branch picks a half turn; it must not reflect."""
    u = np.asarray(u, dtype=float)
    r = _rotation_between(u, -u)
    _assert_proper_rotation_taking(r, u, -u)
    # a half turn about an axis perpendicular to u: applied twice it is the identity
    np.testing.assert_allclose(r @ r, np.eye(3), atol=1e-12)
    assert np.trace(r) == pytest.approx(-1.0, abs=1e-12)
    # generic and equal directions too
    rng = np.random.default_rng(int(1000 * abs(u).sum()))
    for v in (rng.normal(size=3), 2.0 * u):
        _assert_proper_rotation_taking(_rotation_between(u, v), u, v)


def test_align_paper_recovers_a_half_turn_of_the_midline():
    """Rest TT-TD pointing exactly backwards from the mesh's: the opposite-vectors branch runs."""
    half_turn = np.diag([-1.0, 1.0, -1.0])  # about y, which is perpendicular to TT-TD
    t = SimilarityTransform(1.2, half_turn, np.array([0.01, -0.02, 0.005]))
    nodes = {n: t.apply(np.asarray(p)) for n, p in RHOMBUS.items()}
    rest = {n: np.asarray(p) for n, p in RHOMBUS.items()}
    assert np.cross(rest["TT"] - rest["TD"], nodes["TT"] - nodes["TD"]) == pytest.approx(np.zeros(3), abs=1e-15)
    fitted = align_paper(rest, nodes)
    np.testing.assert_allclose(fitted.rotation, half_turn, atol=1e-9)
    for n, p in rest.items():
        np.testing.assert_allclose(fitted.apply(p), nodes[n], atol=1e-11)


def test_align_paper_steps():
    """TT-TD lands exactly on P_TT-P_TD in direction; TL-TR in the plane perpendicular to it."""
    rng = np.random.default_rng(9)
    nodes = {n: np.asarray(p) * 1.5 + rng.normal(0, 0.002, 3) for n, p in RHOMBUS.items()}
    fitted = align_paper(RHOMBUS, nodes)
    moved = {n: fitted.apply(np.asarray(p)) for n, p in RHOMBUS.items()}
    long_s, long_p = moved["TT"] - moved["TD"], nodes["TT"] - nodes["TD"]
    np.testing.assert_allclose(np.cross(long_s, long_p), 0, atol=1e-12)
    axis = long_p / np.linalg.norm(long_p)
    lat_s = moved["TL"] - moved["TR"]
    lat_p = nodes["TL"] - nodes["TR"]
    lat_s, lat_p = lat_s - axis * (axis @ lat_s), lat_p - axis * (axis @ lat_p)
    np.testing.assert_allclose(np.cross(lat_s, lat_p), 0, atol=1e-12)
    assert lat_s @ lat_p > 0
    centroid = np.mean(list(moved.values()), axis=0)
    np.testing.assert_allclose(centroid, np.mean(list(nodes.values()), axis=0), atol=1e-12)


def test_best_scale_minimises_the_sum_of_distances():
    rng = np.random.default_rng(4)
    a = rng.normal(size=(4, 3))
    b = 1.3 * a + rng.normal(0, 0.3, a.shape)
    best = _best_scale(a, b)
    grid = np.linspace(0.5, 2.5, 20001)
    costs = np.linalg.norm(grid[:, None, None] * a - b, axis=2).sum(axis=1)
    assert best == pytest.approx(grid[np.argmin(costs)], abs=2e-4)


def test_align_paper_needs_its_sensors():
    with pytest.raises(TonguevisError, match="missing TR"):
        align_paper({k: v for k, v in RHOMBUS.items() if k != "TR"}, RHOMBUS)
