"""A virtual electropalatograph: the Reading EPG's 62 electrodes on the speaker's palate, lit where the simulated
tongue touches it, and the indices EPG studies report.

Layout (the Reading EPG palate; Hardcastle, Gibbon & Jones 1991): 8 rows from the alveolar ridge (row 1) to the
end of the hard palate (row 8), spaced evenly along the palate's midline (:mod:`tonguevis.sim.palate_regions`:
its front to the end of its hard palate, the velum's hinge on a speaker's palate); 8 columns across the palate at
each row, spaced evenly over 90 % of its width there, row 1 with the 6 middle ones (columns 2-7).  An electrode
is contacted in a frame when the tongue's upper surface right under it, or a node of that surface within the
electrode's cell (half-way to its neighbours), lies within :data:`ELECTRODE_TOUCH` (1 mm) of the palate of that
frame (its velum lifted as simulated).

Indices per frame (:func:`epg_indices`):

* ``percent_contact``: the share of the 62 electrodes contacted, %;
* ``cog``: the centre of gravity, Σ_r w_r n_r / Σ_r n_r with n_r the contacts in row r and row weights 7.5 (row
  1, front) to 0.5 (row 8) in steps of 1 (Hardcastle, Gibbon & Jones 1991; Gibbon & Nicolaidis 1999; emuR's
  ``epgcog``); higher is more anterior; NaN without contact;
* ``anteriority``: Fontdevila, Pallarès & Recasens 1994 (J Phon 22:141-154), log(1·R5/8 + 9·R4/8 + 81·R3/8 +
  729·R2/8 + 4921·R1/6 + 1) / log(5742), R_r the contacts in row r (emuR's ``epgai`` weights 1, 9, 81, 729,
  4921): 0 without contact in rows 1-5, 1 with all of them, weighted to the front;
* ``posteriority``: the same weights from the back (rows 8 to 4: 4921·R8/8 + 729·R7/8 + 81·R6/8 + 9·R5/8 +
  1·R4/8), after Fontdevila et al.'s dorsopalatal measures: weighted to the back of the hard palate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ROWS, COLUMNS = 8, 8
#: The Reading palate's front row has the 6 middle electrodes (columns 2-7, 1-based).
FRONT_ROW = (1, 2, 3, 4, 5, 6)
#: Share of a row's width (where the palate is defined) the columns span (less where the palate narrows).
WIDTH_SHARE = 0.9
#: m: the tongue's surface under an electrode this close to the palate contacts it.  Wider than the contact's
#: TOUCH (0.3 mm): the model's surface is flat between nodes 3-5 mm apart, where a real tongue pressed on the palate
#: conforms to it over the whole patch; 1 mm is about the tissue's compression under an electrode at contact.
ELECTRODE_TOUCH = 1e-3
#: m: a triangle of the tongue with no corner this close to the palate does not touch it (its sides are a few mm).
NEAR = 3e-3
#: Row weights of the centre of gravity, row 1 (front) to row 8.
COG_WEIGHTS = np.arange(7.5, 0.0, -1.0)
#: emuR's ``epgai`` weights, Fontdevila et al. 1994.
FONTDEVILA_WEIGHTS = (1.0, 9.0, 81.0, 729.0, 4921.0)

#: (8, 8) bool: the Reading palate's 62 electrodes on the 8 x 8 grid.
READING = np.array([[r > 0 or c in FRONT_ROW for c in range(COLUMNS)] for r in range(ROWS)])
#: The electrodes' column names, 1-based as EPG papers number them: r1c2 ... r8c8 (62), in READING's order.
ELECTRODES = tuple(f"r{r + 1}c{c + 1}" for r in range(ROWS) for c in range(COLUMNS) if READING[r, c])
INDICES = ("percent_contact", "cog", "anteriority", "posteriority")


@dataclass
class EpgLayout:
    """Where the electrodes are: ``positions`` (8, 8, 3) m in the head frame on the palate at rest (NaN for the
    front row's outer two), and the palate's references (:class:`tonguevis.sim.palate_regions.PalateFrame`)."""

    positions: np.ndarray
    frame: object

    @property
    def used(self) -> np.ndarray:
        """(8, 8) bool: the 62 electrodes of the Reading palate."""
        return np.all(np.isfinite(self.positions), axis=2)

    def cell_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The electrode whose cell holds each place ``xy`` (n, 2) m, head frame: (row, column) indices, -1
        outside every cell.  A cell reaches half-way to the neighbouring rows and columns (as far again beyond
        the outer ones)."""
        xy = np.atleast_2d(np.asarray(xy, dtype=np.float64))
        step = self.frame.length / ROWS
        row = np.floor((self.frame.front - xy[:, 0]) / step).astype(np.int64)
        column = np.full(len(xy), -1, dtype=np.int64)
        inside = (row >= 0) & (row < ROWS)
        for r in range(ROWS):
            ys = self.positions[r, :, 1]
            have = np.flatnonzero(np.isfinite(ys))
            mine = np.flatnonzero(inside & (row == r))
            if len(have) < 2 or len(mine) == 0:
                continue
            half = 0.5 * abs(ys[have[1]] - ys[have[0]])
            distance = np.abs(xy[mine, 1, None] - ys[have][None])
            nearest = np.argmin(distance, axis=1)
            hit = distance[np.arange(len(mine)), nearest] <= half
            column[mine[hit]] = have[nearest[hit]]
        row = np.where(column >= 0, row, -1)
        return row, column


def epg_layout(palate) -> EpgLayout:
    """The Reading layout on ``palate`` (a PalateSurface placed in the head frame)."""
    from tonguevis.sim.palate_regions import palate_frame

    frame = palate_frame(palate)
    x, y = np.asarray(palate.x), np.asarray(palate.y)
    gx, gy = np.meshgrid(x, y)
    own = np.column_stack([gx.ravel(), gy.ravel(), np.asarray(palate.z).ravel()])
    ok = np.isfinite(own[:, 2])
    placed = palate._from_own(own[ok])
    positions = np.full((ROWS, COLUMNS, 3), np.nan)
    row_x = frame.front - (np.arange(ROWS) + 0.5) / ROWS * frame.length
    step = frame.length / ROWS
    spacing = float(np.median(np.abs(np.diff(x)))) * float(getattr(palate, "scale", 1.0)) if len(x) > 1 else 1e-3
    for r, xr in enumerate(row_x):
        band = placed[np.abs(placed[:, 0] - xr) <= max(spacing, 5e-4)]  # the palate's width on the row's line
        if len(band) == 0:
            band = placed[np.abs(placed[:, 0] - xr) <= max(step / 2, 1e-3)]
        if len(band) == 0:
            continue
        left, right = band[:, 1].max(), band[:, 1].min()
        centre = 0.5 * (left + right)
        wanted = [c for c in range(COLUMNS) if r > 0 or c in FRONT_ROW]
        # The palate narrows within a row's band (the front curves in): the columns close in until each one lies
        # on the palate at the row's line.
        for share in np.linspace(WIDTH_SHARE, 0.3, 13):
            half = 0.5 * (left - right) * share
            ys = centre + half * np.linspace(1.0, -1.0, COLUMNS)  # column 1 on the left (y > 0), as EPG plots face it
            row = np.full((COLUMNS, 3), np.nan)
            for c in wanted:
                point = np.array([[xr, ys[c], 0.0]])
                gap, _ = palate.clearance(point)
                if np.isfinite(gap[0]):
                    own_xy = palate._to_own(point)[:, :2]
                    height = palate._interp(own_xy)[0][0]
                    row[c] = palate._from_own(np.array([[own_xy[0, 0], own_xy[0, 1], height]]))[0]
            if np.all(np.isfinite(row[wanted])):
                break
        positions[r] = row
    return EpgLayout(positions, frame)


@dataclass
class Palatogram:
    """Electrode contacts per frame: ``contacts`` (F, 8, 8) bool (False where no electrode), ``times`` (F,) s,
    the ``layout``."""

    contacts: np.ndarray
    times: np.ndarray
    layout: EpgLayout

    def indices(self) -> dict[str, np.ndarray]:
        return epg_indices(self.contacts)

    def rows(self) -> list[dict]:
        """One dict per frame: time_s, each electrode (0/1) and the indices (what ``--epg`` writes)."""
        idx = self.indices()
        out = []
        for f, t in enumerate(self.times):
            row = {"time_s": float(t)}
            flat = self.contacts[f][READING]
            row.update({name: int(v) for name, v in zip(ELECTRODES, flat)})
            row.update({name: float(idx[name][f]) for name in INDICES})
            out.append(row)
        return out


def table_columns() -> dict[str, str]:
    """The columns of a palatogram table (:meth:`Palatogram.rows`), name -> type."""
    return {"time_s": "float", **{name: "int" for name in ELECTRODES}, **{name: "float" for name in INDICES}}


def upper_surface(model) -> tuple[np.ndarray, np.ndarray]:
    """The tongue's upper surface: (k,) node ids (its dorsal nodes) and (t, 3) triangles indexing them (the
    boundary triangles whose corners are all dorsal)."""
    nodes = np.asarray(model.dorsal_nodes)
    faces = np.asarray(model.surface_faces)
    keep = np.all(np.isin(faces, nodes), axis=1)
    local = np.searchsorted(nodes, faces[keep]) if np.all(np.diff(nodes) > 0) else \
        np.vectorize({int(n): i for i, n in enumerate(nodes)}.get)(faces[keep])
    return nodes, np.asarray(local, dtype=np.int64)


def surface_under(points: np.ndarray, triangles: np.ndarray, xy: np.ndarray,
                  candidates: np.ndarray | None = None) -> np.ndarray:
    """The height of a surface at given places: ``points`` (b, k, 3) m per frame, ``triangles`` (t, 3), ``xy``
    (e, 2) m; (b, e, 3) the highest point of the surface straight below or above each place (NaN where no
    triangle covers it).  ``candidates`` (b, t) bool: only these triangles per frame (all by default)."""
    if candidates is None:
        candidates = np.ones((points.shape[0], len(triangles)), dtype=bool)
    fc, tc = np.nonzero(candidates)
    corners = points[fc[:, None], triangles[tc]]  # (p, 3, 3)
    low, high = corners[..., :2].min(axis=1), corners[..., :2].max(axis=1)  # (p, 2)
    # Only the (frame, triangle, place) triples whose triangle's box holds the place: a few per place.
    boxed = np.all((low[:, None] <= xy[None] + 1e-12) & (xy[None] <= high[:, None] + 1e-12), axis=2)  # (p, e)
    pair, e = np.nonzero(boxed)
    f, corners = fc[pair], corners[pair]
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    v0, v1, d = b[:, :2] - a[:, :2], c[:, :2] - a[:, :2], xy[e] - a[:, :2]
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (d[:, 0] * v1[:, 1] - d[:, 1] * v1[:, 0]) / det
        r = (v0[:, 0] * d[:, 1] - v0[:, 1] * d[:, 0]) / det
    inside = (s >= -1e-9) & (r >= -1e-9) & (s + r <= 1 + 1e-9) & (np.abs(det) > 1e-14)
    z = a[:, 2] + s * (b[:, 2] - a[:, 2]) + r * (c[:, 2] - a[:, 2])
    height = np.full((points.shape[0], len(xy)), -np.inf)
    np.maximum.at(height, (f[inside], e[inside]), z[inside])
    out = np.empty(height.shape + (3,))
    out[..., :2] = xy[None]
    out[..., 2] = np.where(np.isfinite(height), height, np.nan)
    return out


def palatogram(motion, frames=None, chunk: int = 64, layout: EpgLayout | None = None) -> Palatogram:
    """The virtual EPG of a motion simulated against a palate (``motion.palate``), at ``frames`` (indices; None:
    every frame): an electrode is contacted where the tongue's upper surface right under it, or a node of it within
    the electrode's cell (:meth:`EpgLayout.cell_of`), is within :data:`ELECTRODE_TOUCH` of the palate of that
    frame.  ``layout``: the motion's palate's (:func:`epg_layout`), when already computed (a view showing frame
    after frame).  ValueError for a motion without a palate."""
    if motion.palate is None:
        raise ValueError("the motion was simulated without a palate: no palatogram")
    layout = layout if layout is not None else epg_layout(motion.palate)
    frames = np.arange(motion.n_frames) if frames is None else np.atleast_1d(np.asarray(frames, dtype=np.int64))
    model = motion.model
    nodes, triangles = upper_surface(model)
    rest = model.mesh.points[nodes]
    lift = motion.velum_lift
    jaw = motion.jaw_offset if motion.jaw_offset is not None else np.zeros((motion.n_frames, 3))
    contacts = np.zeros((len(frames), ROWS, COLUMNS), dtype=bool)
    for start in range(0, len(frames), chunk):
        block = frames[start:start + chunk]
        u = model.displacements(motion.q[block], warping=motion.warping, nodes=nodes)
        points = rest[None] + u + jaw[block][:, None]  # (b, k, 3) head frame
        contacts[start:start + len(block)] = electrode_contacts(points, triangles, motion.palate, layout,
                                                                None if lift is None else lift[block])
    return Palatogram(contacts, np.asarray(motion.times)[frames], layout)


def electrode_contacts(points: np.ndarray, triangles: np.ndarray, palate, layout: EpgLayout,
                       lift: np.ndarray | None = None) -> np.ndarray:
    """(b, 8, 8) bool: the electrodes contacted by the tongue's upper surface ``points`` (b, k, 3) m, head frame
    (its nodes, :func:`upper_surface`'s order) with ``triangles`` (t, 3), against ``palate`` (its velum lifted by
    ``lift`` (b,) m per frame; None: at rest).  What :func:`palatogram` computes per frame, and the live window for
    the frame it draws."""
    points = np.asarray(points, dtype=np.float64)
    b, k = points.shape[:2]
    used = layout.used
    electrodes = layout.positions[used][:, :2]  # (62, 2)
    node_lift = None if lift is None else np.repeat(np.asarray(lift, dtype=np.float64), k)
    # The tongue can touch under an electrode only on a triangle with a corner near the palate.
    node_gap = palate.clearance(points.reshape(-1, 3), lift=node_lift)[0].reshape(b, k)
    near = np.isfinite(node_gap) & (node_gap < NEAR)
    under = surface_under(points, triangles, electrodes, np.any(near[:, triangles], axis=2))  # (b, 62, 3)
    flat = under.reshape(-1, 3)
    gap = np.full(len(flat), np.nan)
    ok = np.isfinite(flat[:, 2])
    if ok.any():
        amounts = None if lift is None else np.repeat(np.asarray(lift, dtype=np.float64), len(electrodes))[ok]
        gap[ok] = palate.clearance(flat[ok], lift=amounts)[0]
    page = np.zeros((b, ROWS, COLUMNS), dtype=bool)
    page[:, used] = (np.isfinite(gap) & (gap < ELECTRODE_TOUCH)).reshape(b, -1)
    # A node touching within an electrode's cell lights it too: the model's contact is a few nodes where a real
    # tongue's patch would cover the electrode.
    f, n = np.nonzero(np.isfinite(node_gap) & (node_gap < ELECTRODE_TOUCH))
    if len(f):
        r, c = layout.cell_of(points[f, n, :2])
        hit = r >= 0
        page[f[hit], r[hit], c[hit]] = True
    return page


def epg_indices(contacts: np.ndarray) -> dict[str, np.ndarray]:
    """The indices of the module docstring for palatograms ``contacts`` (F, 8, 8) bool (or one (8, 8)):
    name -> (F,) array."""
    c = np.asarray(contacts, dtype=np.float64)
    if c.ndim == 2:
        c = c[None]
    rows = c.sum(axis=2)  # (F, 8)
    total = rows.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cog = np.where(total > 0, (rows * COG_WEIGHTS[None]).sum(axis=1) / total, np.nan)
    per = rows / np.array([6.0] + [8.0] * (ROWS - 1))[None]  # each row's share contacted
    w = np.asarray(FONTDEVILA_WEIGHTS)
    norm = np.log(w.sum() + 1.0)
    anteriority = np.log(w[0] * per[:, 4] + w[1] * per[:, 3] + w[2] * per[:, 2] + w[3] * per[:, 1]
                         + w[4] * per[:, 0] + 1.0) / norm
    posteriority = np.log(w[0] * per[:, 3] + w[1] * per[:, 4] + w[2] * per[:, 5] + w[3] * per[:, 6]
                          + w[4] * per[:, 7] + 1.0) / norm
    return {"percent_contact": 100.0 * total / len(ELECTRODES), "cog": cog, "anteriority": anteriority,
            "posteriority": posteriority}


#: s either side of a production's maximum constriction searched for its palatogram (the fullest frame).
CLOSURE_SEARCH = 0.03


def production_epg(motion, table) -> list[dict]:
    """Per production of ``table`` (a :class:`~tonguevis.preprocess.ProductionTable`), the palatogram at its
    closure: the frame of most contact within :data:`CLOSURE_SEARCH` of its maximum constriction (its release
    when the closure was not found), as {"epg_frame_s", "epg_percent_contact", "epg_cog", "epg_anteriority",
    "epg_posteriority"} (NaN without a palate or a time)."""
    empty = {"epg_frame_s": float("nan"), **{f"epg_{name}": float("nan") for name in INDICES}}
    if motion.palate is None:
        return [dict(empty) for _ in table]
    times = np.asarray(motion.times)
    wanted, spans = [], []
    for production in table:
        t = production.closure if np.isfinite(production.closure) else production.release
        if not np.isfinite(t):
            spans.append(None)
            continue
        frames = np.flatnonzero(np.abs(times - t) <= CLOSURE_SEARCH + 1e-9)
        spans.append((len(wanted), len(wanted) + len(frames)))
        wanted.extend(frames.tolist())
    out = []
    if wanted:
        gram = palatogram(motion, np.array(wanted))
        idx = gram.indices()
    for span in spans:
        if span is None or span[0] == span[1]:
            out.append(dict(empty))
            continue
        a, b = span
        best = a + int(np.argmax(idx["percent_contact"][a:b]))
        out.append({"epg_frame_s": float(gram.times[best]),
                    **{f"epg_{name}": float(idx[name][best]) for name in INDICES}})
    return out
