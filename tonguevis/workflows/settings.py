"""One description of a simulation run, for every front end.

The CLI parses its options into a :class:`RunSettings`, the batch stores one
(:class:`tonguevis.batch.settings.BatchSettings` extends it with the batch's own
steps), and the app's model holds one; :func:`build_model` is the only place a
tongue model is built from it, and :meth:`RunSettings.simulate_options` the only
mapping onto :func:`tonguevis.sim.simulate`.  Before, each front end kept its own
copy (argparse plus a dict, ``BatchSettings``, attributes of the main window), and
they drifted apart.
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tonguevis.errors import SimulationError

#: How the sensor nodes are chosen (tonguevis.preprocess.targets.prepare_targets).
LANDMARK_CHOICES = ("speaker", "rule")


@dataclass(frozen=True)
class RunSettings:
    """How one recording is simulated (the defaults are those of ``tonguevis simulate``).

    mesh : a tetrahedral tongue mesh file; None: the shipped tongue.
    mesh_axes : the axes of ``mesh`` (e.g. "-x,-z,-y"), None: already x anterior, y left, z up.
    modes : vibration modes kept (>= 1).
    warping : modal warping (True) or the linear modal model.
    landmarks : "speaker" (sensor nodes snapped to the speaker's layout) or "rule" (the paper's).
    sensor_stiffness : "default", a positive number (in units of the tongue's own stiffness
        at the sensors) or None for hard constraints (the paper's); the CLI's word "hard" is None.
    sensor_patches : "default" (every sensor on the surface, 3 model-mm patches), a radius in metres,
        or None (the sensor nodes pulled by springs only, the sensors left up to 2-6 mm off the surface on
        real recordings; :mod:`tonguevis.sim.patches`).  Ignored by the domains method, whose quadratic
        domains hold the sensor nodes themselves.
    rest : (start_s, end_s) of the rest, None to find it.
    palate : None (no contact), "generic" or a palate file (``tonguevis palate``).
    backend : "warp" (compiled frame loop) or "numpy" (the reference).
    frame : "speaker" (the model placed in the speaker: every figure in the speaker's mm) or "model"
        (the speaker scaled onto the generic tongue, the paper's way); :mod:`tonguevis.sim.placement`.
    tongue_size : in the speaker frame, "adult" (default): the size the rest alignment implies when it
        is an adult tongue's, else the generic adult size (:data:`tonguevis.sim.placement.ADULT`);
        None: the alignment's size whatever it is (the model-frame motion seen in the speaker's
        units); a multiple of the model's (1: the generic adult tongue, the rest sensors fitted onto it).
    """

    mesh: str | None = None
    mesh_axes: str | None = None
    modes: int = 100
    warping: bool = True
    landmarks: str = "speaker"
    sensor_stiffness: float | None | str = "default"
    sensor_patches: float | str | None = "default"
    rest: tuple[float, float] | None = None
    palate: str | None = None
    backend: str = "warp"
    frame: str = "speaker"
    tongue_size: float | str | None = "adult"
    #: "warped", "linear" or "domains" (seed 001's StVK on quadratic domains); None: ``warping`` decides.
    method: str | None = None
    #: the volume kept: each frame projected onto volume-preserving shapes (:mod:`tonguevis.sim.volume`)
    keep_volume: bool = False
    #: the placed tongue bent onto the rest sensors before simulating (:mod:`tonguevis.sim.rest_fit`)
    rest_fit: bool = False

    def __post_init__(self) -> None:
        from tonguevis.sensor_stiffness import sensor_stiffness_value

        if self.mesh is not None:
            object.__setattr__(self, "mesh", os.fspath(self.mesh))
        if isinstance(self.palate, os.PathLike):  # a PalateSurface (made in Python) stays as given
            object.__setattr__(self, "palate", os.fspath(self.palate))
        object.__setattr__(self, "sensor_stiffness", sensor_stiffness_value(self.sensor_stiffness))
        if self.rest is not None:
            object.__setattr__(self, "rest", (float(self.rest[0]), float(self.rest[1])))
        if int(self.modes) < 1:
            raise SimulationError(f"modes must be at least 1, got {self.modes}")
        object.__setattr__(self, "modes", int(self.modes))
        from tonguevis.sim.placement import FRAMES

        if self.frame not in FRAMES:
            raise SimulationError(f"frame must be one of {', '.join(FRAMES)}, got {self.frame!r}")
        from tonguevis.sim.placement import ADULT

        if self.tongue_size is not None and self.tongue_size != ADULT and not (
                isinstance(self.tongue_size, (int, float)) and float(self.tongue_size) > 0):
            raise SimulationError(f"the tongue size must be a positive multiple of the model's, None or {ADULT!r}, "
                                  f"got {self.tongue_size!r}")
        from tonguevis.sim.simulate import METHODS

        if self.method is not None and self.method not in METHODS:
            raise SimulationError(f"method must be one of {', '.join(METHODS)}, got {self.method!r}")
        if self.landmarks not in LANDMARK_CHOICES:
            raise SimulationError(f"landmarks must be one of {', '.join(LANDMARK_CHOICES)}, got {self.landmarks!r}")

    def replace(self, **changes: Any) -> "RunSettings":
        """A copy with ``changes`` (field name -> value)."""
        return dataclasses.replace(self, **changes)

    def simulate_options(self) -> dict:
        """Keyword arguments of :func:`tonguevis.sim.simulate` (the model and the palate aside: see
        :func:`build_model` and :meth:`palate_surface`)."""
        return dict(modes=self.modes, warping=self.warping, landmarks=self.landmarks, rest=self.rest,
                    sensor_stiffness=self.sensor_stiffness, sensor_patches=self.sensor_patches, backend=self.backend,
                    frame=self.frame, tongue_size=self.tongue_size, method=self.method,
                    keep_volume=bool(self.keep_volume), rest_fit=bool(self.rest_fit))

    def palate_surface(self):
        """The :class:`~tonguevis.palate.PalateSurface` of ``palate`` (None: no contact)."""
        if self.palate is None:
            return None
        from tonguevis.palate import load_palate

        return load_palate(self.palate)

    def model_fields(self) -> tuple:
        """What the tongue model depends on: two settings with equal fields share one model."""
        return (self.mesh, self.mesh_axes)


def build_model(settings: RunSettings | str | os.PathLike | None = None):
    """The tongue model of ``settings`` (its ``mesh`` and ``mesh_axes``; a path alone is a mesh
    file): the shipped tongue when there is no mesh."""
    from tonguevis.sim import TongueModel

    if settings is None or isinstance(settings, (str, os.PathLike)):
        settings = RunSettings(mesh=settings)
    if settings.mesh is None:
        return TongueModel.default()
    options = {"axes": settings.mesh_axes} if settings.mesh_axes else {}
    return TongueModel.from_mesh(Path(settings.mesh), **options)
