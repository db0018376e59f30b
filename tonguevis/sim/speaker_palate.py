"""The speaker's palate as the tongue meets it: traced where it was traced, from the speech elsewhere, a velum
that lifts.

A palate traced with a probe covers the hard palate as far back as the probe went (on the shared OSN12 traces,
48 mm of midline ending some 30 mm behind the incisors' level); the dorsum at /k/ works further back, on the
soft palate, which also lifts in speech to close the nose.  Raising the whole traced palate until the dorsum
fits under it (as tonguevis did) took the traced hard palate 6-9 mm away from the tongue tip, so the tip
never met it at /t/.  Here (:func:`speaker_palate`):

* **traced**: the cells the probe went over (:data:`tonguevis.palate.MIN_SUPPORT` trace points within
  :data:`tonguevis.palate.SUPPORT_RADIUS`, its mirror image not counted) keep their fitted heights, except
  where the speech's own sensors go above them: there the surface is raised, locally and smoothly, as far as
  they ask (:data:`COIL_HALF` above each coil's centre).  Both are the speaker; where they disagree the
  speech of the session shown wins, and the figures say by how much (on OSN12, whose traces and speech were
  recorded without shared head references, the blade sensor went 2-7 mm above the densely traced palate 27 mm
  behind the tip's place while the tip stayed 1-3 mm under it: the sittings' head frames differ by a tilt);
* **estimated**: behind and beside it, the generic roof joined to the traced edge
  (:func:`tonguevis.palate.joined_palate`), raised wherever the sensors went above it, broadly
  (:data:`ESTIMATE_RAISE_REACH`: a roof, not a groove along the sensors' path) and, on the soft palate,
  wherever the tongue at rest lies above it;
* **velum**: behind the traced hard palate's posterior end (the hinge), ``lift_shape`` rises from 0 to 1 over
  :data:`VELUM_RAMP`; each frame's lift (m) is the least that keeps every sensor over the soft palate
  :data:`COIL_HALF` under it (held over a few frames: the velum does not flicker), so the dorsum's own
  measurement lifts it and it sits on the dorsum at a /k/ closure.

The result is the palate at rest (a :class:`~tonguevis.palate.PalateSurface` with ``traced`` and ``lift_shape``
on its grid) and the lift per frame: ``surface.lifted(lift[i])`` is the palate at frame i
(:meth:`tonguevis.sim.motion.Motion.palate_at`).  All in the simulation's (head) frame, metres.
"""

from __future__ import annotations

import numpy as np

from tonguevis.palate import MIN_SUPPORT, PalateSurface, joined_palate

#: m: from a coil's centre to its top (an NDI Wave coil with its glue is about 1 mm thick): the palate is at least
#: this far above a sensor.
COIL_HALF = 0.5e-3
#: m: behind the hinge (the traced hard palate's posterior end) the velum's share of a lift rises to 1 over this.
VELUM_RAMP = 4e-3
#: The least share of a lift at a sensor's place for that sensor to lift the velum (nearer the hinge it raises
#: the static estimate instead).
MIN_VELUM_SHARE = 0.5
#: m: a point's need to raise the palate is met in full within RAISE_FLAT of it (x, y; more than a grid cell's
#: half-diagonal, so the cells around it all reach it) and fades out by RAISE_REACH.
RAISE_FLAT, RAISE_REACH = 1.5e-3, 6e-3
#: m: on the estimated palate (no trace there) a point's need is met in full within ESTIMATE_RAISE_FLAT and fades
#: out by ESTIMATE_RAISE_REACH.  The generic roof lies up to 10 mm under the dorsum's path at /k/ (OSN12); raised
#: within 6 mm it became a groove along that path whose walls held the dorsum beside TD down while TD rose into it:
#: the cone (TD moving 1.4-1.8x its neighbours at the closures).  A roof raised over 15 mm lets the dorsum rise as a
#: whole (1.06-1.12) and still meets the dorsum at 8-10 of 10 closures.  The traced palate keeps the narrow raise.
ESTIMATE_RAISE_FLAT, ESTIMATE_RAISE_REACH = 4e-3, 15e-3
#: Frames either side over which a lift is held (the velum moves with the tongue, not with each sample's noise).
LIFT_HOLD = 2
#: Per sensor, the share of its samples highest above the palate left out of the envelope: a glitch of the
#: tracker (a few samples, millimetres off) must not move the palate.
OUTLIER_SHARE = 0.005
#: m: the half-width about the midline where the hinge (the traced hard palate's posterior end) is looked for.
HINGE_BAND = 5e-3


def speaker_palate(placed: PalateSurface, generic: PalateSurface | None, sensors: np.ndarray,
                   rest_points: np.ndarray | None = None) -> tuple[PalateSurface, np.ndarray, dict]:
    """(palate at rest, lift (F,) m, info) for a simulation; see the module docstring.

    placed : the speaker's palate (from traces) in the simulation's frame; its ``support`` tells what was traced
        (a palate without one, e.g. a mesh file, is taken as traced wherever it is defined).
    generic : the generic roof in the same frame (None: no estimate beyond the traced part).
    sensors : (F, S, 3) m, the sensors over the session in the same frame (NaN where missing): their envelope.
    rest_points : (k, 3) m, the tongue's upper surface at rest (the soft palate is raised to clear it).
    info : {"traced_share", "traced_raised_mm" (the most any traced cell was raised), "traced_raised_share" (of
    the traced cells raised over 0.5 mm), "traced_raised_at_mm" ((x, y) where most), "estimated_raised_mm",
    "hinge_x_mm", "velum_lift_max_mm", "velum_lift_median_mm", "velum_lifted_frames"}.
    """
    sensors = np.asarray(sensors, dtype=np.float64)
    traced_only = placed.with_grid(np.where(_traced(placed), placed.z, np.nan))
    points = _envelope_points(traced_only, sensors)
    whole = joined_palate(traced_only, generic) if generic is not None else _as_query_grid(traced_only)
    x, y = np.asarray(whole.x), np.asarray(whole.y)
    gx, gy = np.meshgrid(x, y)
    cells = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])
    z = np.array(whole.z, dtype=np.float64)
    traced = np.isfinite(traced_only.clearance(cells)[0]).reshape(gx.shape) & np.isfinite(z)
    hinge = _hinge(gx, gy, traced)
    ramp = np.clip((hinge - gx) / VELUM_RAMP, 0.0, 1.0) if hinge is not None else np.zeros_like(gx)
    shape = np.where(traced | ~np.isfinite(z), 0.0, ramp * ramp * (3.0 - 2.0 * ramp))
    # Raised where the sensors went above it (but over the velum, which lifts for them frame by frame) and, on
    # the soft palate, where the tongue at rest lies above it.
    over_velum = _at(whole, shape, points) >= MIN_VELUM_SHARE
    lifted = [points[~over_velum] + [0.0, 0.0, COIL_HALF]]
    if rest_points is not None and len(rest_points):
        rest = np.asarray(rest_points, dtype=np.float64)
        lifted.append(rest[_at(whole, shape, rest) > 0.0])
    raise_by = _raise_to(gx, gy, z, np.concatenate(lifted), np.isfinite(z))
    # where nothing was traced the sensors raise the roof broadly (ESTIMATE_RAISE_REACH says why)
    raise_by = np.maximum(raise_by, _raise_to(gx, gy, z, lifted[0], np.isfinite(z) & ~traced,
                                              ESTIMATE_RAISE_REACH, ESTIMATE_RAISE_FLAT))
    z = z + raise_by
    rest_surface = whole.with_grid(z, traced=traced, lift_shape=shape, support=None,
                                   metadata={**placed.metadata, **{k: v for k, v in whole.metadata.items()
                                                                   if k == "joined"}})
    lift = velum_lift(rest_surface, sensors)
    on_traced = np.where(traced, raise_by, 0.0)
    most = np.unravel_index(int(np.argmax(on_traced)), on_traced.shape)
    info = {"traced_share": float(traced.sum() / max(np.isfinite(z).sum(), 1)),
            "traced_raised_mm": float(1e3 * on_traced.max()) if on_traced.size else 0.0,
            "traced_raised_share": float(np.sum(on_traced > 0.5e-3) / max(traced.sum(), 1)),
            "traced_raised_at_mm": [float(1e3 * gx[most]), float(1e3 * gy[most])],
            "estimated_raised_mm": float(1e3 * np.where(traced, 0.0, raise_by).max()) if raise_by.size else 0.0,
            "hinge_x_mm": None if hinge is None else 1e3 * float(hinge),
            "velum_lift_max_mm": float(1e3 * lift.max()) if len(lift) else 0.0,
            "velum_lift_median_mm": float(1e3 * np.median(lift)) if len(lift) else 0.0,
            "velum_lifted_frames": int(np.sum(lift > 0))}
    rest_surface.metadata["speaker_palate"] = info
    return rest_surface, lift, info


def _envelope_points(palate: PalateSurface, sensors: np.ndarray) -> np.ndarray:
    """(k, 3) the sensors' samples the palate must clear: every valid sample but, per sensor, the
    :data:`OUTLIER_SHARE` highest above ``palate`` (or above the lowest of its samples where it has none)."""
    kept = []
    for k in range(sensors.shape[1]):
        own = sensors[:, k]
        own = own[np.all(np.isfinite(own), axis=1)]
        if len(own) == 0:
            continue
        gap = palate.clearance(own)[0]
        height = np.where(np.isfinite(gap), -gap, own[:, 2] - own[:, 2].min())
        drop = int(np.floor(OUTLIER_SHARE * len(own)))
        kept.append(own[np.argsort(height)[:len(own) - drop]] if drop else own)
    return np.concatenate(kept) if kept else np.zeros((0, 3))


def velum_lift(palate: PalateSurface, sensors: np.ndarray) -> np.ndarray:
    """(F,) m: each frame's least lift of the velum keeping every sensor over it :data:`COIL_HALF` below it
    (sensors where the velum's share is under :data:`MIN_VELUM_SHARE` left to the static palate), held over
    :data:`LIFT_HOLD` frames either side."""
    sensors = np.asarray(sensors, dtype=np.float64)
    frames, count = sensors.shape[:2]
    if palate.lift_shape is None or frames == 0:
        return np.zeros(frames)
    flat = sensors.reshape(-1, 3)
    ok = np.all(np.isfinite(flat), axis=1)
    need = np.zeros(len(flat))
    if ok.any():
        share = np.full(len(flat), np.nan)
        share[ok] = _at(palate, palate.lift_shape, flat[ok])
        # vertically (a lift is vertical): the height above the sensor, and COIL_HALF along the normal
        # as a vertical distance (1/cos of the slope: the velum is steep behind the hinge)
        own = palate._to_own(flat[ok])
        height, slope = palate._interp(own[:, :2])
        above = np.full(len(flat), np.nan)
        above[ok] = (height - own[:, 2]) * palate.scale
        secant = np.ones(len(flat))
        secant[ok] = np.sqrt(1.0 + np.sum(slope ** 2, axis=1))
        usable = ok & np.isfinite(share) & (share >= MIN_VELUM_SHARE) & np.isfinite(above)
        need[usable] = np.maximum(COIL_HALF * secant[usable] - above[usable], 0.0) / share[usable]
    lift = need.reshape(frames, count).max(axis=1)
    if LIFT_HOLD > 0 and frames > 1:
        from scipy.ndimage import maximum_filter1d

        lift = maximum_filter1d(lift, size=2 * LIFT_HOLD + 1, mode="nearest")
    return lift


def _traced(palate: PalateSurface) -> np.ndarray:
    """(ny, nx) bool on the palate's own grid: where it was traced."""
    defined = np.isfinite(np.asarray(palate.z))
    if palate.support is None:
        return defined
    return defined & (np.asarray(palate.support) >= MIN_SUPPORT)


def _as_query_grid(palate: PalateSurface) -> PalateSurface:
    """The palate resampled on a grid in the query frame (as :func:`joined_palate` returns it)."""
    from tonguevis.palate import GRID_STEP, _height_field

    pts, tris = palate.triangles()
    return _height_field(pts, tris, GRID_STEP, dict(palate.metadata))


def _hinge(gx: np.ndarray, gy: np.ndarray, traced: np.ndarray) -> float | None:
    """x (m) of the traced palate's posterior end about its midline (the median y of its cells), or None."""
    if not traced.any():
        return None
    mid = float(np.median(gy[traced]))
    band = traced & (np.abs(gy - mid) <= HINGE_BAND)
    return float(gx[band].min()) if band.any() else float(gx[traced].min())


def _at(palate: PalateSurface, grid: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``grid`` (a field on the palate's grid) at the (k, 3) query points (bilinear; NaN outside)."""
    own = palate._to_own(points)
    return palate._interp(own[:, :2], grid)[0]


def _raise_to(gx: np.ndarray, gy: np.ndarray, z: np.ndarray, points: np.ndarray, allowed: np.ndarray,
              reach: float = RAISE_REACH, flat: float = RAISE_FLAT) -> np.ndarray:
    """(ny, nx) m: how far to raise each allowed cell so that every point lies under the surface, the raise
    met in full within ``flat`` (m, x-y distance) of each point and fading out by ``reach`` (the largest any
    point asks for; zero elsewhere)."""
    from scipy.spatial import cKDTree

    out = np.zeros_like(z)
    if len(points) == 0 or not allowed.any():
        return out
    # The highest point of each 1 mm column is all that matters: thousands of samples become hundreds.
    column = np.floor(points[:, :2] / 1e-3).astype(np.int64)
    order = np.lexsort((-points[:, 2], column[:, 1], column[:, 0]))
    first = np.ones(len(order), dtype=bool)
    first[1:] = np.any(np.diff(column[order], axis=0) != 0, axis=1)
    points = points[order[first]]
    where = np.flatnonzero(allowed.ravel())
    cells = np.column_stack([gx.ravel()[where], gy.ravel()[where]])
    heights = z.ravel()[where]
    tree = cKDTree(cells)
    best = np.zeros(len(where))
    for p, near in zip(points, tree.query_ball_point(points[:, :2], reach)):
        if not near:
            continue
        near = np.asarray(near)
        d = np.linalg.norm(cells[near] - p[:2], axis=1)
        fade = np.clip((d - flat) / (reach - flat), 0.0, 1.0)
        weight = 1.0 - fade * fade * (3.0 - 2.0 * fade)  # 1 within flat, a smooth step down to 0
        # the cell nearest the point must reach it; the others ease down with distance
        want = (p[2] - heights[near]) * weight
        best[near] = np.maximum(best[near], want)
    out.ravel()[where] = best
    return out
