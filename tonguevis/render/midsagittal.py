"""What the midsagittal views draw at a frame (replay and live alike), computed without Qt.

In the tongue's mid-plane (y = the median of its rest nodes, head frame, x anterior, z up, metres): the tongue's
section (:func:`tonguevis.analysis.section.plane_section`), the palate's section told apart where it was traced
and where it was estimated (a speaker's palate placed for the simulation: its ``traced`` cells; the generic palate
is all "estimated"), its velum lifted as at that frame, the sensors as measured and their trails (the last
:data:`TRAIL_S` seconds), and each tongue sensor's constriction against the palate drawn
(:func:`tonguevis.analysis.constriction.constriction`: degree = shortest distance to the palate, location =
along the palate's midline from its front).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: s of each sensor's past drawn behind it.
TRAIL_S = 0.3
#: The sensors whose constriction the view prints (those of them the recording has).
CONSTRICTING = ("TT", "TB", "TM", "TD", "TL")


@dataclass
class MidsagittalPicture:
    """One frame of the midsagittal view (m, (x, z) in the mid-plane).

    tongue : (n, 2, 2) segments of the tongue's section.  traced, estimated : (k, 2, 2) segments of the palate's
    section where it was traced / estimated (empty without a palate).  sensors : name -> (2,) measured position;
    trails : name -> (t, 2) its last :data:`TRAIL_S` s.  constrictions : (sensor, degree mm, location mm from the
    palate's front, at the palate's edge) per tongue sensor below or above the palate.  time_s : the frame's time.
    """

    time_s: float
    tongue: np.ndarray
    traced: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    estimated: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    sensors: dict = field(default_factory=dict)
    trails: dict = field(default_factory=dict)
    constrictions: list = field(default_factory=list)

    def lines(self) -> list[str]:
        """The constriction at the cursor as the view prints it: "TT 3.6 mm at 29 mm from the palate's front"."""
        out = []
        for name, degree, location, edge in self.constrictions:
            where = "beyond the palate's edge" if edge else f"at {location:.0f} mm from the palate's front"
            out.append(f"{name} {degree:.1f} mm {where}" if degree >= 0 else f"{name} {-degree:.1f} mm above the "
                       f"palate {where}")
        return out

    def all_points(self) -> np.ndarray:
        """(p, 2) every point drawn (for the view's bounds)."""
        parts = [a.reshape(-1, 2) for a in (self.tongue, self.traced, self.estimated) if len(a)]
        parts += [np.atleast_2d(v) for v in self.sensors.values()]
        return np.vstack(parts) if parts else np.zeros((0, 2))


def split_palate(palate) -> tuple[np.ndarray, np.ndarray]:
    """(traced faces, estimated faces) of a drawn palate (:class:`~tonguevis.render.drawing.ShownPalate`), by its
    placed surface's traced cells (all estimated when unknown, and for the generic palate)."""
    faces = np.asarray(palate.faces)
    traced = getattr(palate.surface, "traced", None)
    if traced is None or palate.generic:
        return faces[:0], faces
    centres = np.asarray(palate.points, dtype=np.float64)[faces].mean(axis=1)
    own = palate.surface._to_own(centres)
    share = palate.surface._interp(own[:, :2], np.asarray(traced, dtype=np.float64))[0]
    mine = np.nan_to_num(share) >= 0.5
    return faces[mine], faces[~mine]


def palate_sections(palate, y: float, index: int | None = None, faces=None, drawn=None) -> tuple[np.ndarray, np.ndarray]:
    """(traced, estimated) (k, 2, 2) segments (x, z) where the plane ``y`` cuts the drawn palate at frame ``index``
    (its velum lifted then; None: at rest); ``faces``: :func:`split_palate`'s, when already computed; ``drawn``:
    the palate's points at that frame, when already computed (:meth:`ShownPalate.points_at`)."""
    from tonguevis.analysis.section import plane_section

    traced, estimated = faces if faces is not None else split_palate(palate)
    if drawn is None:
        drawn = palate.points if index is None else palate.points_at(index)
    return plane_section(drawn, traced, y), plane_section(drawn, estimated, y)


class MidsagittalSection:
    """The midsagittal pictures of one simulated session (``session.frames``, ``session.shown_palate``)."""

    def __init__(self, session):
        from tonguevis.render.scene import surface_faces

        self.session = session
        frames = session.frames
        motion = frames.motion
        self.faces = surface_faces(motion.model)
        self.y = float(np.median(np.asarray(motion.model.mesh.points)[:, 1]))
        self.palate = getattr(session, "shown_palate", None)
        self._palate_faces = None if self.palate is None else split_palate(self.palate)
        names = list(motion.sensor_names)
        self.names = names
        self.constricting = [n for n in CONSTRICTING if n in names]
        self._geometry = None

    def region(self, below: float = 0.025) -> np.ndarray:
        """(p, 2) points spanning where the view should look: the palate's section and the sensors over the whole
        motion, down to ``below`` m under the lowest sensor (the tongue's upper part, where it meets the palate;
        the tongue's base below is cut off); the whole tongue's section without a palate."""
        motion = self.session.frames.motion
        first = self.at(0)
        measured = np.asarray(motion.targets, dtype=np.float64)[:, :, [0, 2]].reshape(-1, 2)
        measured = measured[np.all(np.isfinite(measured), axis=1)]
        palate = np.vstack([first.traced.reshape(-1, 2), first.estimated.reshape(-1, 2)])
        if not len(palate) or not len(measured):
            return first.all_points()
        low = float(measured[:, 1].min()) - below
        tongue = first.tongue.reshape(-1, 2)
        tongue = tongue[tongue[:, 1] >= low]
        front = max(float(measured[:, 0].max()), float(tongue[:, 0].max()) if len(tongue) else -np.inf) + 0.01
        palate = palate[palate[:, 0] <= front]
        return np.vstack([palate, measured, tongue, [[palate[:, 0].min(), low]]])

    def at(self, i: int) -> MidsagittalPicture:
        """The picture of frame ``i``."""
        from tonguevis.analysis.section import plane_section
        from tonguevis.render.drawing import head_points, jaw_offset_at

        frames, motion = self.session.frames, self.session.frames.motion
        i = int(np.clip(i, 0, frames.n_frames - 1))
        points = head_points(frames, i)
        picture = MidsagittalPicture(float(frames.times[i]), plane_section(points, self.faces, self.y))
        if self._palate_faces is not None:
            picture.traced, picture.estimated = palate_sections(self.palate, self.y, i, self._palate_faces)
        jaw = np.asarray(jaw_offset_at(motion, i), dtype=np.float64)
        measured = np.asarray(motion.targets[i], dtype=np.float64) + jaw  # the sensors as measured, head frame
        rate = 1.0 / max(float(np.median(np.diff(frames.times))) if frames.n_frames > 1 else 0.01, 1e-6)
        start = max(0, i - int(round(TRAIL_S * rate)))
        past = np.asarray(motion.targets[start:i + 1], dtype=np.float64)
        if motion.jaw_offset is not None:
            past = past + np.asarray(motion.jaw_offset[start:i + 1], dtype=np.float64)[:, None]
        for k, name in enumerate(self.names):
            if np.all(np.isfinite(measured[k])):
                picture.sensors[name] = measured[k][[0, 2]]
                picture.trails[name] = past[:, k][:, [0, 2]]
        if self.palate is not None and self.constricting:
            from tonguevis.analysis.constriction import constriction

            which = [self.names.index(n) for n in self.constricting]
            lifted = self.palate.lift is not None and float(self.palate.lift[min(i, len(self.palate.lift) - 1)]) > 0
            found = constriction(self.palate.surface_at(i) if lifted else self.palate.surface, measured[which])
            for n, degree, location, edge in zip(self.constricting, found.degree, found.location, found.at_edge):
                if np.isfinite(degree):
                    picture.constrictions.append((n, 1e3 * float(degree), 1e3 * float(location), bool(edge)))
        return picture
