"""Sensor patches: the tongue's own local deformation under each sensor, to put the sensors on its surface.

The lowest vibration modes are smooth and global: a few of them cannot make the small
local shape a coil glued on the tongue sees, so the compliant sensor springs (the default)
leave the sensors up to 2-4 mm off the surface on real recordings, and a stiffer spring
instead bends the whole tongue.  A patch shape is what the mesh itself does under a load
spread over the surface within ``radius`` of a sensor node beyond what the modes already do
(the residual flexibility K⁻¹f - ΦΛ⁻¹Φᵀf of modal truncation, three per sensor, one per
axis: local by nature), kept to the sensor's neighbourhood: it fades out (a cosine) between
``radius`` and ``reach`` from the sensor node and is zero beyond, so a patch moves nothing
far from its sensor and the model's shape elsewhere, what it predicts, stays the modes' own.

They act after the dynamics, frame by frame: the modes are integrated as before (Newmark,
warping, the compliant projection), then each patch's three coordinates close the gap
between its measured sensor and its node (:func:`close_sensor_gaps`).  Patch shapes are
stiff and local, so treating them quasi-statically is the mode-acceleration method's own
assumption; they are not warped (their rotation matrix columns are zero) but ride on the
global rotation at their node.  The basis [Φ P] is not orthogonal: its stiffness
[[Λ, ΦᵀKP], [PᵀKΦ, PᵀKP]] is kept with it (``basis.info["stiffness"]``) so that the
elastic energy stays ½ xᵀKx of the shape drawn.
"""

from __future__ import annotations

import copy

import numpy as np

from tonguevis.sim.modal import ModalBasis

#: Default radius (m, model frame) of the surface a sensor's load is spread over: about an EMA
#: coil with its glue.  Measured on the shared real recordings (docs/validation.md): with 3/5 mm
#: the held-out sensors are predicted as without patches; wider patches (4/7, 5/10 mm) reach the
#: neighbouring sensors (4-9 mm apart on the model) and cost up to 0.4 mm there.
PATCH_RADIUS = 3e-3
#: How far (m) from its sensor node a patch reaches (it fades out from PATCH_RADIUS to here).
PATCH_REACH = 5e-3
#: Patch shapes nearly dependent on the modes or on each other (overlapping patches) are dropped.
DEPENDENCE = 1e-9
#: m (at PATCH_RADIUS; scaled with it): each sensor's hump, the broad part of its patch: the tissue within
#: HUMP_FLAT of the sensor node moves with it, fading out (a cosine) by HUMP_REACH.  A constricting dorsum
#: moves as a whole: measured on the shared /ka/ 006 and 007 with the speaker's palate, the local shapes alone
#: moved the TD node 1.5-2.3 times as far as the dorsum within 10 mm of it (a cone); with the humps 1.1.
HUMP_FLAT, HUMP_REACH = 6e-3, 15e-3
#: How much dearer the local shapes are than the humps (per metre moved at their own node, squared): the gaps
#: are closed by the humps, the local shapes take what the humps cannot (e.g. where the palate stops a hump).
LOCAL_COST = 100.0
#: Each hump may lean and bend (its HUMP_TILTS leans: the three offsets, then their products), at this cost per
#: metre of lean at HUMP_FLAT; cheaper leans filled the vault better but moved the hump's rim further than any
#: sensor (far-field amplification 1.5-1.7 at cost 0.3, 1.3-1.4 at 5).
HUMP_TILTS, TILT_COST = 6, 5.0


def patch_loads(points: np.ndarray, surface: np.ndarray, nodes: np.ndarray, radius: float) -> np.ndarray:
    """(3n, 3S) unit loads: for each sensor node and axis, a force of 1 N spread over the surface
    nodes within ``radius`` (m) of it with weights (1 - (d/r)²)², the sensor node itself always in."""
    n = len(points)
    loads = np.zeros((3 * n, 3 * len(nodes)))
    for k, node in enumerate(np.asarray(nodes, dtype=np.int64)):
        d = np.linalg.norm(points[surface] - points[node], axis=1)
        weight = np.clip(1.0 - (d / radius) ** 2, 0.0, None) ** 2
        spread = np.zeros(n)
        spread[surface] = weight
        spread[node] = max(spread[node], 1.0)
        spread /= spread.sum()
        for axis in range(3):
            loads[axis::3, 3 * k + axis] = spread
    return loads


def window(points: np.ndarray, centre: np.ndarray, radius: float, reach: float) -> np.ndarray:
    """(n,) 1 within ``radius`` of ``centre``, a cosine down to 0 at ``reach``, 0 beyond (m)."""
    d = np.linalg.norm(points - centre, axis=1)
    fade = 0.5 * (1.0 + np.cos(np.pi * np.clip((d - radius) / max(reach - radius, 1e-12), 0.0, 1.0)))
    return np.where(d <= radius, 1.0, fade)


def augmented_basis(model, basis: ModalBasis, nodes: np.ndarray, radius: float = PATCH_RADIUS,
                    reach: float = PATCH_REACH, hump: tuple[float, float] | None | str = None,
                    humped: list[int] | None = None, unit: bool = True) -> ModalBasis:
    """``basis`` extended by the patch shapes of the sensor ``nodes`` (see the module docstring).

    The first ``basis.n_modes`` columns are ``basis``'s own, then three per sensor (x, y, z of
    its load), then, with ``hump`` ((flat, reach) m; "scaled": :data:`HUMP_FLAT`, :data:`HUMP_REACH`
    scaled as ``radius`` is from :data:`PATCH_RADIUS`; None: none, as motions saved before them),
    twelve more per sensor in ``humped`` (indices into ``nodes``; None: all): its hump (:func:`hump_shapes`).  ``eigenvalues`` holds Λ then the patches'
    own stiffness (diag PᵀKP, for reports); ``info`` holds the whole stiffness ("stiffness", (m+p, m+p))
    and what rebuilds it ({"global_modes", "patch_radius_m", "patch_reach_m", "patch_nodes", "hump_m"}),
    which :func:`augmented_model` and :meth:`tonguevis.sim.Motion.load` use.  With humps and ``unit`` (info
    "unit_at_node"), each sensor's three local shapes and three hump translations are combined so that they move
    their own node by the identity (:func:`_unit_at_own_node`): their costs (:func:`patch_costs`) are then the
    squared metres the node moves, whatever the frame's axes (False: as motions saved before 2026-12-07's).
    """
    import scipy.sparse.linalg as spla

    free = basis.free_dofs
    stiffness = model.stiffness[free][:, free].tocsc()
    points = model.mesh.points
    nodes = np.asarray(nodes, dtype=np.int64)
    loads = patch_loads(points, model.surface_nodes, nodes, radius)[free]
    solved = spla.splu(stiffness).solve(loads)
    phi = basis.phi[free]
    solved -= phi @ ((phi.T @ loads) / basis.eigenvalues[:, None])  # the modes' share: what is left is local
    patches = np.zeros((basis.phi.shape[0], solved.shape[1]))
    patches[free] = solved
    for k, node in enumerate(nodes):
        patches[:, 3 * k:3 * k + 3] *= np.repeat(window(points, points[node], radius, reach), 3)[:, None]
    if isinstance(hump, str):
        hump = (HUMP_FLAT * radius / PATCH_RADIUS, HUMP_REACH * radius / PATCH_RADIUS)
    humped = list(range(len(nodes))) if humped is None else [int(k) for k in humped]
    if hump is not None and humped:
        patches = np.hstack([patches, volume_neutral(hump_shapes(points, nodes[humped], free, *hump), model, free)])
        if unit:
            patches = _unit_at_own_node(patches, nodes, humped)
    else:
        hump = None
    full = np.hstack([basis.phi, patches])
    k_full = model.stiffness @ patches
    coupling = basis.phi.T @ k_full
    own = patches.T @ k_full
    reduced = np.block([[np.diag(basis.eigenvalues), coupling], [coupling.T, 0.5 * (own + own.T)]])
    node_list = [int(v) for v in nodes]
    key = f"{basis.key}-patches-{radius:.6f}-{reach:.6f}-{'-'.join(map(str, node_list))}"
    if hump is not None:
        key += f"-hump-{hump[0]:.6f}-{hump[1]:.6f}-{'-'.join(map(str, humped))}" + ("-unit" if unit else "")
    info = {"global_modes": basis.n_modes, "patch_radius_m": float(radius), "patch_reach_m": float(reach),
            "patch_nodes": node_list, "stiffness": reduced,
            "hump_m": None if hump is None else [float(hump[0]), float(hump[1])],
            "humped": humped if hump is not None else [], "unit_at_node": bool(hump is not None and unit)}
    return ModalBasis(full, np.concatenate([basis.eigenvalues, np.diag(own)]), free, key, info)


def _unit_at_own_node(patches: np.ndarray, nodes: np.ndarray, humped: list[int]) -> np.ndarray:
    """``patches`` (3n, p) with each sensor's local block (3 columns) and each humped sensor's three hump
    translations right-multiplied by the inverse of their 3 x 3 values at the sensor's own node, so that they move
    it by the identity.  The least-cost split between the humps and the local shapes (:func:`close_sensor_gaps`)
    then does not depend on the frame's axes: costed per column, a local block whose node values are not a multiple
    of the identity made a speaker-frame run differ from the model-frame run seen through the fit by 4 µm."""
    out = np.array(patches, copy=True)
    s = len(nodes)
    dofs = 3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)
    blocks = [(k, 3 * k) for k in range(s)] + [(k, 3 * s + j * 3 * (1 + HUMP_TILTS)) for j, k in enumerate(humped)]
    for k, start in blocks:
        cols = slice(start, start + 3)
        out[:, cols] = out[:, cols] @ np.linalg.inv(out[dofs[k], cols])
    return out


#: The sensors without a hump: the tongue tip is thin and free, a /t/ closure presses it onto the palate
#: (:mod:`tonguevis.sim.closures`), and a hump under its coil would carry the pressed tip back down with it
#: (on the shared /ta/ 009 the tip then touched at 0 of 2 closures instead of 2).
UNHUMPED = ("TT",)


def humped_sensors(names) -> list[int]:
    """The indices of the sensors (``names``) that get a hump: all but :data:`UNHUMPED`."""
    return [k for k, name in enumerate(names) if name not in UNHUMPED]


def hump_shapes(points: np.ndarray, nodes: np.ndarray, free: np.ndarray, flat: float, reach: float) -> np.ndarray:
    """(3n, 3(1 + HUMP_TILTS)S) each sensor node's hump: per axis, every node of the mesh (inside too, so the
    tissue under a rising dorsum rises with it) moved along that axis by :func:`window` (1 within ``flat`` m of
    the sensor node, a cosine down to 0 at ``reach``), then the same leaning: the window times each of the
    offsets from the sensor node over ``flat`` and their products (so a hump can tilt and bend, e.g. follow the
    palate down behind the coil and round to its vault).  Columns per sensor: x, y, z, then for each axis its
    HUMP_TILTS leans.  The fixed degrees of freedom (not in ``free``) stay.  Kinematic shapes (made volume
    neutral by :func:`volume_neutral` in :func:`augmented_basis`): their stiffness is the mesh's own (PᵀKP)."""
    n = len(points)
    per = 3 * (1 + HUMP_TILTS)
    shapes = np.zeros((3 * n, per * len(nodes)))
    for k, node in enumerate(np.asarray(nodes, dtype=np.int64)):
        w = window(points, points[node], flat, reach)
        d = (points - points[node]) / flat
        # the leans: the offsets (a tilt) and their products (a bend: a hump rounder or flatter than the window)
        lean = np.column_stack([d, d[:, 0] ** 2, d[:, 1] ** 2, d[:, 0] * d[:, 1], d[:, 2] * d[:, 0],
                                d[:, 2] * d[:, 1], d[:, 2] ** 2])[:, :HUMP_TILTS]
        for axis in range(3):
            shapes[axis::3, per * k + axis] = w
            for b in range(HUMP_TILTS):
                shapes[axis::3, per * k + 3 + 3 * axis + b] = w * lean[:, b]
    fixed = np.ones(3 * n, dtype=bool)
    fixed[free] = False
    shapes[fixed] = 0.0
    return shapes


def volume_neutral(shapes: np.ndarray, model, free: np.ndarray) -> np.ndarray:
    """(3n, c) ``shapes`` less their first-order volume change: each minus its share along the gradient of the
    tongue's volume (the surface's area-weighted normals; the fixed degrees of freedom left out), so a hump
    that lifts the dorsum draws the rest of the surface in by as much, as the nearly incompressible tissue does
    (a hump alone changed the volume by 2.2-3.9 % on the shared real recordings; drawn in, 0.5-1.1 %)."""
    from tonguevis.sim.volume import volume_gradients

    points, tets = model.mesh.points, np.asarray(model.mesh.tets)
    gradient = np.zeros((len(points), 3))
    np.add.at(gradient, tets.ravel(), volume_gradients(points, tets).reshape(-1, 3))
    g = np.zeros(3 * len(points))
    g[free] = gradient.ravel()[free]
    return shapes - np.outer(g, (g @ shapes) / (g @ g))


def patch_costs(basis: ModalBasis, nodes: np.ndarray) -> np.ndarray:
    """(p,) what one unit of each patch coordinate costs in :func:`close_sensor_gaps`: the square of how far
    it moves its own sensor node (a metre of hump or of local shape, whatever the column's scale) times
    :data:`LOCAL_COST` for the local shapes, :data:`TILT_COST` a metre of lean at ``flat`` from the node."""
    m = basis.info["global_modes"]
    s = len(nodes)
    dofs = (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()
    local = np.abs(basis.phi[dofs, m + np.arange(3 * s)])
    cost = [LOCAL_COST * np.maximum(local, 1e-12) ** 2]
    humps = len(basis.info.get("humped") or [])
    if humps:
        cost.append(np.tile(np.concatenate([np.ones(3), np.full(3 * HUMP_TILTS, TILT_COST)]), humps))
    return np.concatenate(cost)


def augmented_model(model, basis: ModalBasis):
    """A shallow copy of ``model`` whose basis of ``basis.n_modes`` modes is ``basis`` (patches
    included) and whose rotation matrix leaves the patch shapes unwarped; the mesh, material
    and FEM matrices are shared."""
    m = basis.info["global_modes"]
    copied = copy.copy(model)
    copied._bases = {**model._bases, basis.n_modes: basis}
    rotation = np.array(model.curl_operator @ basis.phi)
    rotation[:, m:] = 0.0
    copied._rotation_matrices = {**model._rotation_matrices, basis.key: rotation}
    copied._transposed = {}
    copied.base_model = model
    return copied


def global_part(motion):
    """(model, q (F, m)): ``motion``'s modes without its sensor patches, on the model without them
    (the coordinates two recordings share, e.g. for morphing); the motion's own when it has none."""
    patches = motion.metadata.get("sensor_patches")
    if not patches:
        return motion.model, motion.q
    return getattr(motion.model, "base_model", motion.model), motion.q[:, :int(patches["global_modes"])]


def accumulated_rotations(w: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the matrices R̃(w) of modal warping for rotation vectors w (..., 3)."""
    from tonguevis.sim.rotation import accumulated_rotation_matrix

    return accumulated_rotation_matrix(w)


def close_sensor_gaps(basis: ModalBasis, rotation: np.ndarray, nodes: np.ndarray, q: np.ndarray,
                      measured: np.ndarray, warping: bool = True, weight: np.ndarray | None = None,
                      local_only: bool = False) -> np.ndarray:
    """(F, p) patch coordinates that put each measured sensor on its node, frame by frame.

    basis : the augmented basis (:func:`augmented_basis`) of the sensor ``nodes`` (S,);
    rotation : its W (3n, m + p); q : (F, m) the modes' coordinates from the dynamics;
    measured : (F, S, 3) m displacements of the sensors from rest (NaN: not measured; that
    sensor's patch stays at rest).  With warping, node s moves by R̃_s(Φ_s q + P_s c) with R̃_s
    from the modes alone, so P_s c = R̃_s⁻¹ measured_s - Φ_s q: 3S equations.  With the local
    shapes alone (p = 3S) they are solved exactly; with the humps too (p = 6S) by the cheapest
    coordinates (:func:`patch_costs`: the humps first).  ``weight`` (F, S) in [0, 1]: each sensor's
    engagement (:func:`tonguevis.sim.dropouts.engagement`: a sensor back from a dropout is taken up
    over 0.1 s): its gap is closed by that share, so its patch eases in with its spring instead of
    jumping in one frame (with the humps: its node eased from where the other sensors' humps put it to
    its own target, see below).
    """
    m = basis.info["global_modes"]
    nodes = np.asarray(nodes, dtype=np.int64)
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    s = len(nodes)
    phi_s = basis.phi[dofs, :m].reshape(s, 3, m)
    patch_s = basis.phi[dofs, m:]  # (3S, 3S)
    linear = np.einsum("scm,fm->fsc", phi_s, q)
    wanted = np.nan_to_num(measured)
    if warping:
        w = np.einsum("scm,fm->fsc", rotation[dofs, :m].reshape(s, 3, m), q)
        wanted = np.linalg.solve(accumulated_rotations(w), wanted[..., None])[..., 0]
    acting = np.repeat(np.all(np.isfinite(measured), axis=2), 3, axis=1)  # (F, 3S)
    full_gap = np.where(acting, (wanted - linear).reshape(len(q), 3 * s), 0.0)
    engaged = np.ones_like(full_gap) if weight is None else np.repeat(
        np.clip(np.asarray(weight, dtype=np.float64), 0.0, 1.0), 3, axis=1)
    gap = full_gap * engaged
    p = patch_s.shape[1]
    if local_only and p > 3 * s:  # the humps at rest
        out = np.zeros((len(q), p))
        out[:, :3 * s] = _local(patch_s[:, :3 * s], acting, gap)
        return out
    if p == 3 * s:  # the local shapes alone: as many as the gaps, solved exactly
        return _local(patch_s, acting, gap)
    inverse_cost = 1.0 / patch_costs(basis, nodes)
    humped = basis.info["humped"]
    inverse_cost[3 * s:] *= np.tile(np.r_[np.ones(3), np.zeros(3 * HUMP_TILTS)], len(humped))  # tilts: the palate's
    out = _least_cost(patch_s, inverse_cost, humped, acting, gap)
    # A sensor being taken up (or let go) around a dropout: its row's target eases from where the others' humps
    # put its node without it to its own gap.  Closing "w x its gap" instead pinned its node where the modes had
    # it the moment it came back, and every overlapping hump jumped to make room (2.6 mm a frame on the shared
    # /ka/ 006 with TB lost for 1 s; 0.8 mm with the local shapes alone).
    partial = acting & (engaged < 1.0)
    frames = np.flatnonzero(partial.any(axis=1))
    if len(frames):
        free = _least_cost(patch_s, inverse_cost, humped, acting[frames] & ~partial[frames], full_gap[frames])
        there = free @ patch_s.T  # (f, 3S) what the patches do at each sensor's node without the easing ones
        w = engaged[frames]
        eased = np.where(partial[frames], w * full_gap[frames] + (1.0 - w) * there, full_gap[frames])
        out[frames] = _least_cost(patch_s, inverse_cost, humped, acting[frames], eased)
    return out


def _least_cost(patch_s: np.ndarray, inverse_cost: np.ndarray, humped: list, acting: np.ndarray,
                gap: np.ndarray) -> np.ndarray:
    """(F, p) the cheapest patch coordinates (inverse costs ``inverse_cost`` (p,), 0: a column left out) closing
    ``gap`` (F, 3S) at the sensors' rows ``patch_s`` (3S, p), c = C⁻¹Aᵀ(AC⁻¹Aᵀ)⁻¹g; a sensor not ``acting``
    (F, 3S) has its columns out (its coordinates 0) and its row the identity."""
    s = patch_s.shape[0] // 3
    column_acting = np.hstack([acting, np.repeat(acting[:, ::3][:, humped], 3 * (1 + HUMP_TILTS),
                                                 axis=1)])  # (F, p): each column's sensor measured
    a = np.where(acting[:, :, None] & column_acting[:, None, :], patch_s[None], 0.0)  # (F, 3S, p)
    mats = np.einsum("fip,p,fjp->fij", a, inverse_cost, a)
    idx = np.arange(3 * s)
    mats[:, idx, idx] += np.where(acting, 0.0, 1.0)
    y = np.linalg.solve(mats, gap[:, :, None])[:, :, 0]
    return np.einsum("fip,p,fi->fp", a, inverse_cost, y)


def _local(patch_s: np.ndarray, acting: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """(F, 3S) the local shapes' coordinates closing ``gap`` (F, 3S) exactly with their rows ``patch_s``
    (3S, 3S); a sensor not measured (``acting`` (F, 3S) False): its patch at rest (its row and column the
    identity)."""
    mats = np.where(acting[:, :, None] & acting[:, None, :], patch_s[None], 0.0)
    idx = np.arange(patch_s.shape[0])
    mats[:, idx, idx] += np.where(acting, 0.0, 1.0)
    return np.linalg.solve(mats, gap[:, :, None])[:, :, 0]


def physics_text(motion) -> str:
    """The tongue's physics in a motion's summary: "modal warping", "linear" or, for the domains
    method, "nonlinear tissue (StVK, Luo et al. 2017)"."""
    if motion.metadata.get("method") == "domains":
        return "nonlinear tissue (StVK, Luo et al. 2017)"
    return "modal warping" if motion.warping else "linear"


def modes_text(motion, long: bool = True) -> str:
    """"100 modes", or with sensor patches "100 modes + 15 sensor patch shapes (3 mm, the sensors on
    the surface)" (``long``) / "100 modes + sensor patches"; the domains method's degrees of freedom
    are no modes: "6 quadratic domains (180 degrees of freedom)"."""
    domains = motion.metadata.get("domains") if motion.metadata.get("method") == "domains" else None
    if domains:
        return f"{domains['domains']} quadratic domains ({domains['dofs']} degrees of freedom)"
    patches = motion.metadata.get("sensor_patches")
    if not patches:
        return f"{motion.q.shape[1]} modes"
    if not long:
        return f"{patches['global_modes']} modes + sensor patches"
    return (f"{patches['global_modes']} modes + {patches['shapes']} sensor patch shapes ({patches['radius_mm']:g} mm, "
            "the sensors on the surface)")
