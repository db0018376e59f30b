"""Kinematic baseline: interpolate sensor displacements over their rest positions.

No mesh, no physics: the displacement of a point is a radial-basis
interpolation (SciPy's ``RBFInterpolator``, linear kernel φ(r) = -r plus a
degree-1 polynomial) of the displacements of the driving sensors, with the
sensors' rest positions as centres.  It reproduces affine displacement fields
exactly, which is what a few sensors on a tongue can pin down.

A degree-1 polynomial in 3-D has four terms, so it needs four centres not on
one plane; EMA layouts rarely give that (a leave-one-out run on four tongue
sensors keeps three; the Haskins midline layout keeps two).  The centres are
therefore expressed in the coordinates of their own affine hull (the k = rank
principal directions of the centred rest positions, k <= n - 1, directions
whose singular value is below ``RANK_TOLERANCE`` of the largest dropped), the
query point is projected onto that hull, and the interpolation runs in k
dimensions.  With n = k + 1 centres the RBF part vanishes and the result is
plain affine (barycentric) interpolation: linear along the line through two
sensors, planar over three.  Off the hull the displacement field is taken
constant along the dropped directions.
"""

from __future__ import annotations

import numpy as np

from tonguevis.errors import TonguevisError

#: Principal directions of the centres whose singular value is below this
#: fraction of the largest are dropped (nearly collinear / coplanar layouts).
RANK_TOLERANCE = 0.02


def hull_coordinates(centres: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of ``centres`` (n, 3) and ``points`` (k, 3) in the centres' affine hull.

    Returns (centre_coords (n, d), point_coords (k, d)) with d the numerical
    rank of the centred centres (0 <= d <= min(n - 1, 3)); points off the hull
    are projected orthogonally onto it.  Units as given (metres).
    """
    centres = np.asarray(centres, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    origin = centres.mean(axis=0)
    _, sv, vt = np.linalg.svd(centres - origin, full_matrices=False)
    rank = int(np.sum(sv > RANK_TOLERANCE * sv[0])) if len(sv) and sv[0] > 0 else 0
    basis = vt[:rank].T  # (3, d)
    return (centres - origin) @ basis, (points - origin) @ basis


def interpolation_weights(centres, points) -> np.ndarray:
    """(k, n) weights a with value(points) = a @ value(centres) for any field.

    The interpolant is linear in the data, so interpolating the identity gives
    the weights once for all frames.  centres : (n, 3) rest positions of the
    driving sensors (n >= 1); points : (k, 3) where to predict.  With one
    centre the field is constant (weights 1).
    """
    centres = np.asarray(centres, dtype=np.float64)
    points = np.atleast_2d(np.asarray(points, dtype=np.float64))
    if centres.ndim != 2 or centres.shape[1] != 3 or len(centres) < 1:
        raise TonguevisError(f"kinematic interpolation needs (n, 3) centres with n >= 1, got {centres.shape}")
    if not (np.all(np.isfinite(centres)) and np.all(np.isfinite(points))):
        raise TonguevisError("kinematic interpolation: centres and points must be finite")
    n = len(centres)
    centre_xy, point_xy = hull_coordinates(centres, points)
    if centre_xy.shape[1] == 0:
        return np.full((len(points), n), 1.0 / n)
    from scipy.interpolate import RBFInterpolator

    rbf = RBFInterpolator(centre_xy, np.eye(n), kernel="linear", degree=1)
    return rbf(point_xy)

