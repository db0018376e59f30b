"""What the 3D scene draws for one frame, in the head or the jaw frame, against which palate (no Qt).

The tongue is simulated in the jaw frame; :class:`~tonguevis.render.frames.MotionFrames`
holds it so.  :func:`draw_frame` turns one frame into what the scene shows in
the chosen frame of reference (:mod:`tonguevis.sim.reference`): in the head frame
the tongue, its sensors and the jaw surface move by the jaw's translation and the
palate stays; in the jaw frame the tongue and jaw stay and the palate moves by
minus the translation.  The tongue-palate geometry, and so the contact colouring,
is the same in both.  The window's 3D views and the video export share it.

:class:`ShownPalate` is the palate the views draw and measure against, in the
model frame: the speaker's, placed exactly as the simulation placed it
(:func:`tonguevis.sim.simulate.placed_palate`), or the shipped generic one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tonguevis.sim.reference import describe, jaw_moves

from tonguevis._logging import logger

#: Colour range of the "contact" mode: distance to the palate in mm (0 = touching).
CONTACT_RANGE_MM = (0.0, 10.0)
#: A node this close to the palate touches it (the contact area of ``motion.contact_area``).
TOUCH_MM = 0.3


@dataclass
class ShownPalate:
    """A palate the views draw and measure against, in the model frame.

    surface : :class:`~tonguevis.palate.PalateSurface` (model frame) for distances.
    points : (k, 3) float32 and faces : (f, 3) int, the mesh drawn.
    label : what it is, for captions ("generic palate", "speaker's palate osn12.stl").
    simulated : whether the motion was simulated against it (contact kept).
    raised_mm : how far the placement raised its traced part to lie above the sensors.
    lift : (F,) m, the velum's lift per frame (None: a rigid palate); ``share`` (k,) how much of a lift
        each drawn point takes (:meth:`points_at`).
    """

    surface: object
    points: np.ndarray
    faces: np.ndarray
    label: str
    simulated: bool = False
    raised_mm: float = 0.0
    generic: bool = False
    lift: np.ndarray | None = None
    share: np.ndarray | None = None

    def points_at(self, index: int) -> np.ndarray:
        """(k, 3) float32: the drawn points at frame ``index`` (the velum lifted; ``points`` when rigid)."""
        if self.lift is None or self.share is None:
            return self.points
        out = self.points.copy()
        out[:, 2] += np.float32(self.lift[min(max(int(index), 0), len(self.lift) - 1)]) * self.share
        return out

    def surface_at(self, index: int):
        """The surface at frame ``index`` (the velum lifted) for distances."""
        if self.lift is None:
            return self.surface
        return self.surface.lifted(float(self.lift[min(max(int(index), 0), len(self.lift) - 1)]))

    def clearance_mm(self, points: np.ndarray, index: int | None = None) -> np.ndarray:
        """(k,) float32 distance (mm) of head-frame ``points`` (k, 3) below the palate (at frame ``index``: its velum
        lifted as then; None: at rest); negative inside, NaN off it."""
        points = np.asarray(points, dtype=np.float64)
        if index is None or self.lift is None:
            gap, _ = self.surface.clearance(points)
        else:
            amount = float(self.lift[min(max(int(index), 0), len(self.lift) - 1)])
            gap, _ = self.surface.clearance(points, lift=np.full(len(points), amount))
        return (1e3 * gap).astype(np.float32)

    @property
    def regions(self):
        """The palate's references for saying where on it something is
        (:class:`tonguevis.sim.palate_regions.PalateFrame`), computed once."""
        cached = getattr(self, "_regions", None)
        if cached is None:
            from tonguevis.sim.palate_regions import palate_frame

            cached = self._regions = palate_frame(self.surface)
        return cached

    def describe(self) -> str:
        text = self.label + (" (contact kept in the simulation)" if self.simulated else " (drawn only: simulated "
                                                                                          "without contact)")
        info = self.surface.metadata.get("speaker_palate")
        if info:  # a speaker's palate made whole from the speech: what was traced, estimated, moved
            from tonguevis.sim.plausibility import speaker_palate_words

            text += speaker_palate_words(info).replace("; the speaker's palate:", ":", 1)
        elif self.raised_mm > 0.05:
            text += f", raised {self.raised_mm:.1f} mm above where the sensors went"
        return text


def smooth_outline_triangles(surface, blur_cells: float = 2.5) -> tuple[np.ndarray, np.ndarray]:
    """(n, 3) vertices and (f, 3) triangles of ``surface`` (a PalateSurface) with a smooth outline.

    The height field is defined on a mask of grid cells, whose edge drawn as the cells' own
    triangles is a staircase (a sawtooth along the palate's sides).  Here the mask is blurred
    (``blur_cells`` grid steps) and the surface cut where the blur crosses one half: the outline
    follows the mask's, rounded, the heights untouched inside (outside the mask they are the
    nearest defined ones, only under the cut's last half cell).  Drawing only: the simulation and
    the figures use the height field itself.
    """
    import pyvista as pv
    from scipy import ndimage

    z = np.asarray(surface.z, dtype=np.float64)
    ok = np.isfinite(z)
    if ok.all() or not ok.any():
        return surface.triangles()
    nearest = ndimage.distance_transform_edt(~ok, return_distances=False, return_indices=True)
    filled = z[tuple(nearest)]
    inside = ndimage.gaussian_filter(ok.astype(np.float64), blur_cells)
    gx, gy = np.meshgrid(surface.x, surface.y)  # (ny, nx), as z
    grid = pv.StructuredGrid(gx, gy, filled)
    grid.point_data["inside"] = inside.ravel(order="F")  # StructuredGrid's points run x fastest per column
    cut = grid.clip_scalar(scalars="inside", value=0.5, invert=False).extract_surface(algorithm="dataset_surface")
    cut = cut.triangulate()
    if cut.n_cells == 0:
        return surface.triangles()
    faces = cut.faces.reshape(-1, 4)[:, 1:]
    return surface._from_own(np.asarray(cut.points)), faces


def speaker_palate(surface, label: str, simulated: bool = True, raised_mm: float = 0.0, lift=None) -> ShownPalate:
    """A placed palate (model frame) drawn as its own height field, its outline smoothed
    (:func:`smooth_outline_triangles`); ``lift`` (F,) m: its velum's lift per frame."""
    try:
        points, faces = smooth_outline_triangles(surface)
    except Exception as exc:  # drawing only: the cells' own triangles will do
        logger.info("palate drawn without a smoothed outline: %s", exc)
        points, faces = surface.triangles()
    share = None
    if lift is not None and getattr(surface, "lift_shape", None) is not None:
        own = surface._to_own(np.asarray(points, dtype=np.float64))
        share = np.nan_to_num(surface._interp(own[:, :2], surface.lift_shape)[0]).astype(np.float32) * surface.scale
    return ShownPalate(surface, np.asarray(points, dtype=np.float32), np.asarray(faces), label, simulated,
                       float(raised_mm), bool(surface.metadata.get("generic", False)),
                       None if share is None else np.asarray(lift, dtype=np.float64), share)


def generic_shown(simulated: bool = False, model=None) -> ShownPalate | None:
    """The shipped generic palate: its own mesh drawn, its height field measured; None if absent.

    In the model frame, or placed with ``model`` when that is the model placed in a speaker
    (:mod:`tonguevis.sim.placement`): the generic palate belongs to the generic tongue."""
    from tonguevis.palate import generic_palate
    from tonguevis.sim.placement import in_model_frame, model_placement

    from tonguevis.mesh.default import context_surface_path
    from tonguevis.mesh.surfaces import read_surface

    try:
        surface = generic_palate()
        points, faces = read_surface(context_surface_path("palate"))
    except Exception as exc:  # context is optional: never block the app on it
        logger.warning("generic palate not shown: %s", exc)
        return None
    placement = model_placement(model)
    if placement is not None:
        surface, points = in_model_frame(surface, model), placement.apply(points)
    return ShownPalate(surface, np.asarray(points, dtype=np.float32), np.asarray(faces), "generic palate",
                       simulated, 0.0, True)


def palate_label(spec) -> str:
    """A caption for what the user chose: "generic palate" or "speaker's palate NAME"."""
    from pathlib import Path

    from tonguevis.palate import PalateSurface

    if spec is None or str(spec) == "generic":
        return "generic palate"
    if isinstance(spec, PalateSurface):
        if spec.metadata.get("generic"):
            return "generic palate"
        sources = spec.metadata.get("file") or spec.metadata.get("source") or []
        name = Path(sources[0] if isinstance(sources, list) and sources else str(sources)).name if sources else ""
        return f"speaker's palate {name}".rstrip()
    return f"speaker's palate {Path(spec).name}"


@dataclass
class FrameDrawing:
    """One frame as the scene draws it (float32, metres, in ``reference``)."""

    index: int
    reference: str
    points: np.ndarray
    scalars: np.ndarray | None
    sensor_points: np.ndarray
    targets: np.ndarray
    context_offsets: dict = field(default_factory=dict)
    caption: str = ""
    #: name -> (k, 3) a context surface's points at this frame where it changes shape (the velum lifting), before
    #: its offset; surfaces not named keep their shape.
    context_shapes: dict = field(default_factory=dict)


def jaw_offset_at(motion, i: int) -> np.ndarray:
    """(3,) float32 the jaw's translation at frame ``i`` (zeros without jaw motion)."""
    if not jaw_moves(motion):
        return np.zeros(3, dtype=np.float32)
    return np.asarray(motion.jaw_offset[i], dtype=np.float32)


def head_points(frames, i: int) -> np.ndarray:
    """(n, 3) float32 the tongue's nodes at frame ``i`` in the head frame (where the palate is)."""
    return frames.points[i] + jaw_offset_at(frames.motion, i)


def draw_frame(session, i: int, reference: str = "head", mode: str = "displacement") -> FrameDrawing:
    """Frame ``i`` of the session's motion in ``reference`` ("head" or "jaw"), coloured by ``mode``.

    "contact" colours by the distance (mm) to the session's palate, measured in the
    head frame (the same in both frames); the other modes come from ``session.frames``.
    """
    from tonguevis.sim.reference import check_reference

    check_reference(reference)
    frames, motion = session.frames, session.frames.motion
    jaw = jaw_offset_at(motion, i)
    tongue = jaw if reference == "head" else np.zeros(3, dtype=np.float32)
    palate = getattr(session, "shown_palate", None)
    if mode == "contact":
        scalars = palate.clearance_mm(frames.points[i] + jaw, index=i) if palate is not None else None
    else:
        scalars = frames.scalars[mode][i] if mode in frames.scalars else None
    offsets = {"jaw": tongue.astype(np.float64), "palate": (tongue - jaw).astype(np.float64)}
    caption = describe(reference, jaw_moves(motion))
    shapes = {}
    if palate is not None and palate.lift is not None and not palate.generic:
        shapes["palate"] = palate.points_at(i)  # the velum as lifted then
    return FrameDrawing(i, reference, frames.points[i] + tongue, scalars, frames.sensor_points[i] + tongue,
                        frames.targets[i] + tongue, offsets, caption, shapes)


def contact_at(session, i: int) -> dict:
    """What the status bar says about the palate at frame ``i``: {"penetration_mm", "contact_area_mm2"
    (None when the motion was simulated without contact), "closest_mm" (the upper surface's closest
    approach, negative inside; None where no palate lies above), "sensors_above" (the driving sensors
    measured above the palate: there the sensor wins, and the tongue around it may be inside), "place" (where on
    the palate the tongue touches it: "front-centre", "back-left"...; "" where it does not)}, against the palate
    as at that frame (its velum lifted)."""
    motion = session.frames.motion
    out = {"penetration_mm": None, "contact_area_mm2": None, "closest_mm": None, "sensors_above": [], "place": ""}
    if getattr(motion, "penetration", None) is not None:
        out["penetration_mm"] = float(1e3 * motion.penetration[i])
    if getattr(motion, "contact_area", None) is not None:
        out["contact_area_mm2"] = float(1e6 * motion.contact_area[i])
    palate = getattr(session, "shown_palate", None)
    if palate is not None:
        frames = session.frames
        nodes = _dorsal(session)
        points = head_points(frames, i)[nodes]
        gap = palate.clearance_mm(points, index=i)
        out["closest_mm"] = float(np.nanmin(gap)) if np.isfinite(gap).any() else None
        touching = np.isfinite(gap) & (gap < TOUCH_MM)
        if touching.any():
            from tonguevis.sim.palate_regions import place_of

            out["place"] = place_of(palate.regions, points[touching])
        sensors = palate.clearance_mm(frames.targets[i] + jaw_offset_at(motion, i), index=i)  # as measured
        out["sensors_above"] = [name for name, g in zip(motion.sensor_names, sensors) if g < 0]
    return out


def contact_line(session, i: int, reference: str) -> str:
    """One status-bar line: the frame of reference, the palate, penetration and contact area at frame ``i``."""
    motion = session.frames.motion
    parts = [describe(reference, jaw_moves(motion)).split(":")[0]]
    palate = getattr(session, "shown_palate", None)
    if palate is None:
        return parts[0] + "; no palate"
    figures = contact_at(session, i)
    parts.append(palate.label)
    if figures["penetration_mm"] is not None:
        parts.append(f"penetration {figures['penetration_mm']:.2f} mm, contact area {figures['contact_area_mm2']:.0f} mm²")
    else:
        parts.append("no contact simulated")
    if figures["place"]:
        parts.append(f"touching {figures['place']}")
    if figures["closest_mm"] is not None:
        parts.append(f"closest {figures['closest_mm']:.1f} mm")
    if figures["sensors_above"]:
        parts.append(f"{', '.join(figures['sensors_above'])} above the palate (sensors win)")
    return " · ".join(parts)


def _dorsal(session) -> np.ndarray:
    """The model's upward-facing surface nodes (all nodes for a model that does not know them)."""
    model = session.frames.motion.model
    nodes = getattr(model, "dorsal_nodes", None)
    return np.arange(model.mesh.n_nodes) if nodes is None else np.asarray(nodes)
