"""Alignment of the rest sensor positions onto mesh landmark nodes (§3.1).

Two ways, both returning a :class:`SimilarityTransform` (uniform scale, proper
rotation, translation; applied as ``s R p + t``):

* :func:`align_paper` - the paper's recipe for the rhombus TT, TD, TL, TR:
  translate the sensor centroid onto the node centroid, rotate TT-TD onto
  P_TT-P_TD, rotate about that axis to bring TL-TR onto P_TL-P_TR, then the
  uniform scale about the centroid minimising the sum of sensor-node distances.
* :func:`fit_similarity` - the least-squares similarity (Umeyama) for any
  >= 3 non-collinear sensors, or, for midsagittal-only layouts (TT, TB, TBK
  on the midline), a fit that keeps the midsagittal plane: rotation about the
  lateral y axis only, scale and translation fitted in x-z.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from tonguevis.errors import TonguevisError
from tonguevis.preprocess._rigid import fit_rotations


@dataclass(frozen=True, eq=False)
class SimilarityTransform:
    """p -> scale * rotation @ p + translation.

    scale : float > 0; rotation : (3, 3) proper rotation; translation : (3,)
    in the target's units (metres).
    """

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self):
        rotation = np.asarray(self.rotation, dtype=np.float64)
        translation = np.asarray(self.translation, dtype=np.float64)
        if rotation.shape != (3, 3) or translation.shape != (3,):
            raise TonguevisError(f"a similarity needs a (3, 3) rotation and a (3,) translation, got "
                                 f"{rotation.shape} and {translation.shape}")
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise TonguevisError(f"a similarity needs a positive finite scale, got {self.scale}")
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) or np.linalg.det(rotation) < 0:
            raise TonguevisError("the rotation of a similarity must be a proper rotation matrix")
        object.__setattr__(self, "scale", float(self.scale))
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation", translation)

    def apply(self, points) -> np.ndarray:
        """points (..., 3) -> transformed (..., 3)."""
        points = np.asarray(points, dtype=np.float64)
        return self.scale * points @ self.rotation.T + self.translation

    def inverse(self) -> "SimilarityTransform":
        rt = self.rotation.T
        return SimilarityTransform(1.0 / self.scale, rt, -(rt @ self.translation) / self.scale)

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) homogeneous matrix."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.rotation
        m[:3, 3] = self.translation
        return m

    def __matmul__(self, other: "SimilarityTransform") -> "SimilarityTransform":
        """Composition: (self @ other).apply(p) == self.apply(other.apply(p))."""
        return SimilarityTransform(self.scale * other.scale, self.rotation @ other.rotation,
                                   self.scale * self.rotation @ other.translation + self.translation)


def _as_points(name: str, points) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise TonguevisError(f"{name} must be an (S, 3) array of points, got shape {points.shape}")
    if not np.all(np.isfinite(points)):
        raise TonguevisError(f"{name} holds NaN or infinite coordinates")
    return points


def _rank_ratio(points: np.ndarray) -> float:
    """Second singular value over the first of the centred points (0 if collinear)."""
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return float(s[1] / s[0]) if s[0] > 0 else 0.0


def fit_similarity(source, target, midsagittal: bool = False) -> SimilarityTransform:
    """The similarity T minimising sum |T(source_i) - target_i|^2.

    source, target : (S, 3) corresponding points.  Without ``midsagittal``,
    needs S >= 3 not (nearly) collinear; the rotation is proper (never a
    reflection; Umeyama 1991).  With ``midsagittal=True`` the midsagittal
    plane is kept: the rotation turns about the y (lateral) axis only, scale
    and translation are fitted in x-z (S >= 2), and the y translation makes
    the y centroids coincide.  Raises TonguevisError for unusable input,
    including points within 2 % of their extent of a straight line.
    """
    source = _as_points("source", source)
    target = _as_points("target", target)
    if source.shape != target.shape:
        raise TonguevisError(f"source and target differ in shape: {source.shape} vs {target.shape}")
    if midsagittal:
        return _fit_midsagittal(source, target)
    # Nearly collinear points leave the rotation about their line undetermined.
    if len(source) < 3 or _rank_ratio(source) < 0.02 or _rank_ratio(target) < 0.02:
        raise TonguevisError(
            f"a 3-D similarity fit needs >= 3 non-collinear points (got {len(source)}, "
            "nearly collinear?); for midline-only layouts use midsagittal=True")
    rotation, scale, src_c, tgt_c, _ = fit_rotations(source, target)
    return SimilarityTransform(float(scale), rotation, tgt_c - scale * rotation @ src_c)


def _fit_midsagittal(source: np.ndarray, target: np.ndarray) -> SimilarityTransform:
    if len(source) < 2:
        raise TonguevisError(f"a midsagittal fit needs >= 2 points, got {len(source)}")
    xz = [0, 2]
    a = source[:, xz] - source[:, xz].mean(axis=0)
    b = target[:, xz] - target[:, xz].mean(axis=0)
    spread = float(np.sum(a * a))
    if spread <= 0 or np.sum(b * b) <= 0:
        raise TonguevisError("a midsagittal fit needs points that differ in x or z")
    # 2-D Umeyama with complex numbers: b ~ s e^{i theta} a, (x, z) as x + i z.
    ac = a[:, 0] + 1j * a[:, 1]
    bc = b[:, 0] + 1j * b[:, 1]
    product = np.sum(np.conj(ac) * bc)
    theta = float(np.angle(product))
    scale = float(abs(product) / spread)
    c, s = np.cos(theta), np.sin(theta)
    # x' = c x - s z ; z' = s x + c z: a rotation about y, proper (det = 1).
    rotation = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    translation = target.mean(axis=0) - scale * rotation @ source.mean(axis=0)
    return SimilarityTransform(scale, rotation, translation)


def _rotation_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The smallest proper rotation turning direction u onto direction v."""
    u = u / np.linalg.norm(u)
    v = v / np.linalg.norm(v)
    axis = np.cross(u, v)
    sin, cos = np.linalg.norm(axis), float(np.dot(u, v))
    if sin < 1e-12:
        if cos > 0:
            return np.eye(3)
        # Opposite: half a turn about any axis perpendicular to u.
        perp = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        perp /= np.linalg.norm(perp)
        return 2.0 * np.outer(perp, perp) - np.eye(3)
    k = axis / sin
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + sin * kx + (1 - cos) * kx @ kx


def align_paper(rest: dict, nodes: dict, names=("TT", "TD", "TL", "TR")) -> SimilarityTransform:
    """The alignment of §3.1 mapping rest sensor positions onto mesh nodes.

    rest, nodes : {name: (3,)} for TT, TD, TL, TR (``names`` to use others:
    front-midline, back-midline, left, right).  Translation of centroids, a
    rotation taking TT-TD onto P_TT-P_TD, a rotation about P_TT-P_TD taking
    the component of TL-TR perpendicular to it onto that of P_TL-P_TR, then
    the uniform scale about the centroid minimising sum_i |s S_i - P_i| (the
    paper's sum of distances, not squared).
    """
    missing = [n for n in names if n not in rest or n not in nodes]
    if missing:
        raise TonguevisError(f"align_paper needs sensors and nodes {', '.join(names)}; "
                             f"missing {', '.join(missing)}")
    front, back, left, right = names
    s = {n: np.asarray(rest[n], dtype=np.float64) for n in names}
    p = {n: np.asarray(nodes[n], dtype=np.float64) for n in names}
    src_c = np.mean([s[n] for n in names], axis=0)
    tgt_c = np.mean([p[n] for n in names], axis=0)
    long_s, long_p = s[front] - s[back], p[front] - p[back]
    if np.linalg.norm(long_s) == 0 or np.linalg.norm(long_p) == 0:
        raise TonguevisError(f"{front} and {back} coincide; align_paper cannot orient the midline")
    first = _rotation_between(long_s, long_p)
    axis = long_p / np.linalg.norm(long_p)
    lat_s = first @ (s[left] - s[right])
    lat_p = p[left] - p[right]
    lat_s -= axis * np.dot(axis, lat_s)
    lat_p -= axis * np.dot(axis, lat_p)
    if np.linalg.norm(lat_s) < 1e-12 or np.linalg.norm(lat_p) < 1e-12:
        raise TonguevisError(f"{left}-{right} is parallel to {front}-{back}; the second rotation is undefined")
    # Rotation about `axis` by the signed angle from lat_s to lat_p.
    angle = np.arctan2(np.dot(axis, np.cross(lat_s, lat_p)), np.dot(lat_s, lat_p))
    kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    second = np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
    rotation = second @ first
    a = np.array([rotation @ (s[n] - src_c) for n in names])
    b = np.array([p[n] - tgt_c for n in names])
    scale = _best_scale(a, b)
    return SimilarityTransform(scale, rotation, tgt_c - scale * rotation @ src_c)


def _best_scale(a: np.ndarray, b: np.ndarray) -> float:
    """argmin_s sum_i |s a_i - b_i| (convex in s), started from the least-squares scale."""
    least_squares = float(np.sum(a * b) / np.sum(a * a))
    cost = lambda s: float(np.sum(np.linalg.norm(s * a - b, axis=1)))  # noqa: E731
    upper = max(2.0 * abs(least_squares), 1e-9) * 4.0
    result = minimize_scalar(cost, bounds=(0.0, upper), method="bounded", options={"xatol": 1e-12})
    best = float(result.x)
    return best if cost(best) < cost(least_squares) else max(least_squares, 1e-12)
