"""One description of a simulation run: :class:`RunSettings`, for the library and every front end.

``tonguevis.simulate(recording)``, ``tonguevis simulate FILE``, the app, the batch, the corpus steps, the
validation and the live mode all simulate with a :class:`RunSettings`; its defaults are the one set of
defaults (the front ends' since the redesign).  The CLI parses its options into one
(:func:`tonguevis.cli._common.run_settings_of`), the batch hashes one into its cache keys
(:meth:`RunSettings.key`), the app's model holds one.  Any runner also takes its fields as keyword
overrides: ``simulate(recording, settings, modes=60)``.

The choices of each field live here too (:data:`METHODS`, :data:`FRAMES`, :data:`LANDMARKS`, :data:`ADULT`,
:data:`BACKENDS`), so nothing that validates a setting imports a runner.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tonguevis.errors import SimulationError

#: ``method``: "warped" (modal warping, the paper's), "linear" (modal, no warping), "domains" (seed 001's
#: StVK on quadratic domains, :mod:`tonguevis.sim.domains`).
METHODS = ("warped", "linear", "domains")
#: ``frame``: "speaker" (the model placed in the speaker: figures in the speaker's mm) or "model" (the
#: speaker scaled onto the generic tongue, the paper's way); :mod:`tonguevis.sim.placement`.
FRAMES = ("speaker", "model")
#: ``landmarks``: the sensor nodes snapped to the speaker's layout, or the paper's placement rule.
LANDMARKS = ("speaker", "rule")
#: ``backend``: the compiled frame loop (warp-lang) or the NumPy reference.
BACKENDS = ("warp", "numpy")
#: ``tongue_size=ADULT``: the size the rest alignment implies when it is an adult tongue's, else the generic
#: adult size (:mod:`tonguevis.sim.placement`).
ADULT = "adult"
#: ``sensor_stiffness="default"``: the sensor springs in units of the tongue's own point stiffness at the
#: sensors (:func:`tonguevis.sim.constrained.point_stiffness`), measured best on real recordings.
DEFAULT_SENSOR_STIFFNESS = 20.0


@dataclass(frozen=True)
class RunSettings:
    """How one recording is simulated.  The defaults are everyone's: ``tonguevis.simulate(recording)``
    simulates as ``tonguevis simulate FILE`` and the app do.

    mesh : a tetrahedral tongue mesh file; None: the shipped tongue (:func:`build_model`).
    mesh_axes : the axes of ``mesh`` (e.g. "-x,-z,-y"), None: already x anterior, y left, z up.
    modes : vibration modes kept (>= 1).
    method : one of :data:`METHODS` (default "warped"); ``warping`` follows it.
    warping : True for "warped", False for "linear" (given alone, it chooses between the two).
    landmarks : "speaker" (sensor nodes snapped to the speaker's layout) or "rule" (the paper's).
    sensor_stiffness : "default" (:data:`DEFAULT_SENSOR_STIFFNESS`), a positive number (in units of the
        tongue's own stiffness at the sensors) or None for hard constraints (the paper's; the CLI's "hard").
    sensor_patches : "default" (every sensor on the surface, 3 model-mm patches), a radius in metres, or None
        (the sensor nodes pulled by springs only, the sensors left up to 2-6 mm off the surface on real
        recordings; :mod:`tonguevis.sim.patches`).  The domains method's quadratic domains hold the sensor
        nodes themselves.
    rest : (start_s, end_s) of the rest, a :class:`~tonguevis.preprocess.rest.RestChoice`, or None to find it.
    palate : None (no contact), "generic", a palate file (``tonguevis palate``) or a
        :class:`~tonguevis.palate.PalateSurface`.
    backend : "warp" (compiled frame loop) or "numpy" (the reference).
    frame : "speaker" or "model" (:data:`FRAMES`).
    tongue_size : in the speaker frame, "adult" (default): the size the rest alignment implies when it is an
        adult tongue's, else the generic adult size; None: the alignment's size whatever it is (the
        model-frame motion seen in the speaker's units); a multiple of the model's (1: the generic adult
        tongue, the rest sensors fitted onto its surface).
    keep_volume : each frame projected onto volume-preserving shapes (:mod:`tonguevis.sim.volume`).
    rest_fit : the placed tongue bent onto the rest sensors before simulating (:mod:`tonguevis.sim.rest_fit`).
    smooth_window : Savitzky-Golay window (samples) of the sensor trajectories, None: not smoothed.
    tolerance : the Newton tolerance of the constraint solve (m); None: the method's own (1e-8 modal,
        1e-7 domains).
    closures : with a palate, at each stop's closure found on the recording the tip and blade (/t/) or the
        dorsum about its coil (/k/) are pressed onto the palate (:mod:`tonguevis.sim.closures`); False: only the
        sensors and the contact.
    humps : with sensor patches, each sensor but the tip also moves the tissue around it as a hump (flat within
        6 model-mm, gone by 15 mm) before the local shapes close what is left, and with a palate the humps are
        flattened against it (:mod:`tonguevis.sim.patch_contact`): a dorsum at /k/ rises as a whole instead of
        in a cone under its coil.  The humps are kinematic shapes, volume-neutral to first order; False: the
        local shapes alone (a peak under each coil at a constriction; the README's figures).
    """

    mesh: str | None = None
    mesh_axes: str | None = None
    modes: int = 100
    warping: bool = True
    landmarks: str = "speaker"
    sensor_stiffness: float | None | str = "default"
    sensor_patches: float | str | None = "default"
    rest: Any = None
    palate: Any = None
    backend: str = "warp"
    frame: str = "speaker"
    tongue_size: float | str | None = ADULT
    method: str | None = None
    keep_volume: bool = False
    rest_fit: bool = False
    smooth_window: int | None = None
    tolerance: float | None = None
    closures: bool = True
    humps: bool = True

    def __post_init__(self) -> None:
        from tonguevis.sensor_stiffness import sensor_stiffness_value

        if self.mesh is not None:
            object.__setattr__(self, "mesh", os.fspath(self.mesh))
        if isinstance(self.palate, os.PathLike):  # a PalateSurface (made in Python) stays as given
            object.__setattr__(self, "palate", os.fspath(self.palate))
        object.__setattr__(self, "sensor_stiffness", sensor_stiffness_value(self.sensor_stiffness))
        if self.rest is not None and not hasattr(self.rest, "interval"):  # a RestChoice stays as given
            rest = tuple(self.rest)
            if len(rest) != 2:
                raise SimulationError(f"rest must be (start_s, end_s), got {self.rest!r}")
            object.__setattr__(self, "rest", (float(rest[0]), float(rest[1])))
        if isinstance(self.modes, bool) or int(self.modes) < 1:
            raise SimulationError(f"modes must be at least 1, got {self.modes}")
        object.__setattr__(self, "modes", int(self.modes))
        _check_choice("frame", self.frame, FRAMES)
        _check_choice("landmarks", self.landmarks, LANDMARKS)
        _check_choice("backend", self.backend, BACKENDS)
        if self.method is None:
            object.__setattr__(self, "method", "warped" if self.warping else "linear")
        _check_choice("method", self.method, METHODS)
        object.__setattr__(self, "warping", self.method == "warped")
        if self.tongue_size is not None and self.tongue_size != ADULT and not (
                isinstance(self.tongue_size, (int, float)) and not isinstance(self.tongue_size, bool)
                and float(self.tongue_size) > 0):
            raise SimulationError(f"the tongue size must be a positive multiple of the model's, None or {ADULT!r}, "
                                  f"got {self.tongue_size!r}")
        patches = self.sensor_patches
        if patches is not None and patches != "default" and not (
                isinstance(patches, (int, float)) and not isinstance(patches, bool) and 0 < float(patches) < 0.05):
            raise SimulationError(f"the sensor patches' radius must be a positive number of metres (under 0.05), "
                                  f"'default' or None, got {patches!r}")
        if self.smooth_window is not None and int(self.smooth_window) < 3:
            raise SimulationError(f"smooth_window must be at least 3 samples or None, got {self.smooth_window}")
        if self.tolerance is not None and not float(self.tolerance) > 0:
            raise SimulationError(f"tolerance must be a positive length in metres or None, got {self.tolerance}")
        for name in ("keep_volume", "rest_fit", "closures", "humps"):
            object.__setattr__(self, name, bool(getattr(self, name)))

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The fields' names (what :meth:`replace` and every runner's overrides accept)."""
        return tuple(f.name for f in dataclasses.fields(cls))

    def replace(self, **changes: Any) -> "RunSettings":
        """A copy with ``changes`` (field name -> value).  ``warping`` given without ``method`` chooses
        between "warped" and "linear"; an unknown name raises SimulationError listing the settings."""
        unknown = sorted(set(changes) - set(self.names()))
        if unknown:
            raise SimulationError(f"unknown run setting(s) {', '.join(unknown)}; the settings are "
                                  f"{', '.join(self.names())}")
        if "warping" in changes and "method" not in changes:
            changes["method"] = "warped" if changes["warping"] else "linear"
        elif "method" in changes and "warping" not in changes:
            changes["warping"] = changes["method"] != "linear"
        return dataclasses.replace(self, **changes)

    @property
    def sensor_stiffness_value(self) -> float | None:
        """The sensor stiffness as a number (the default resolved), None for hard constraints."""
        return DEFAULT_SENSOR_STIFFNESS if self.sensor_stiffness == "default" else self.sensor_stiffness

    @property
    def newton_tolerance(self) -> float:
        """``tolerance``, or the method's own when None (m)."""
        if self.tolerance is not None:
            return float(self.tolerance)
        return 1e-7 if self.method == "domains" else 1e-8

    def palate_surface(self):
        """The :class:`~tonguevis.palate.PalateSurface` of ``palate`` (None: no contact)."""
        if self.palate is None:
            return None
        from tonguevis.palate import load_palate

        return load_palate(self.palate)

    def model_fields(self) -> tuple:
        """What the tongue model depends on: two settings with equal fields share one model."""
        return (self.mesh, self.mesh_axes)

    def key(self, model: bool = True) -> dict:
        """Every field as JSON-able values, files by their content (what a cache key hashes): two settings
        with equal keys simulate the same motion of the same recording.  ``model=False`` leaves out the mesh
        (a cache that hashes the model itself)."""
        out: dict[str, Any] = {}
        for name in self.names():
            value = getattr(self, name)
            if name in ("mesh", "mesh_axes") and not model:
                continue
            if name == "mesh" and value is not None:
                value = _file_digest(value)
            elif name == "rest" and hasattr(value, "as_dict"):
                value = value.as_dict()
            elif name == "palate" and value is not None and value != "generic":
                value = _palate_digest(value)
            out[name] = value
        return out


def _check_choice(name: str, value, choices: tuple) -> None:
    if value not in choices:
        what = {"method": "simulation method"}.get(name, name)
        raise SimulationError(f"unknown {what} {value!r}; choose one of {', '.join(choices)}")


def _file_digest(path) -> str:
    """``sha256:<hex>`` of a file's bytes (its path when it cannot be read: the error comes when it is used)."""
    try:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        return "sha256:" + h.hexdigest()
    except OSError:
        return os.fspath(path)


def _palate_digest(palate) -> str:
    """``sha256:<hex>`` of a palate's grid and placement (a file read as :func:`~tonguevis.palate.load_palate`
    reads it; its path when it cannot be read: the error comes when it is used)."""
    import numpy as np

    if isinstance(palate, (str, Path)):
        from tonguevis.errors import TonguevisError
        from tonguevis.palate import load_palate

        try:
            palate = load_palate(palate)
        except (TonguevisError, OSError):
            return os.fspath(palate)
    h = hashlib.sha256()
    for array in (palate.x, palate.y, palate.z, palate.rotation, palate.scale, palate.translation):
        h.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    return "sha256:" + h.hexdigest()


def run_settings(settings: "RunSettings | None" = None, **changes: Any) -> RunSettings:
    """``settings`` (default: the defaults) with ``changes`` applied (field name -> value)."""
    settings = settings if settings is not None else RunSettings()
    return settings.replace(**changes) if changes else settings


def split_overrides(options: dict) -> tuple[dict, dict]:
    """``options`` split into (run settings' fields, the rest)."""
    names = set(RunSettings.names())
    return ({k: v for k, v in options.items() if k in names}, {k: v for k, v in options.items() if k not in names})


def build_model(settings: "RunSettings | str | os.PathLike | None" = None):
    """The tongue model of ``settings`` (its ``mesh`` and ``mesh_axes``; a path alone is a mesh
    file): the shipped tongue when there is no mesh."""
    from tonguevis.sim.model import TongueModel

    if settings is None or isinstance(settings, (str, os.PathLike)):
        settings = RunSettings(mesh=settings)
    if settings.mesh is None:
        return TongueModel.default()
    options = {"axes": settings.mesh_axes} if settings.mesh_axes else {}
    return TongueModel.from_mesh(Path(settings.mesh), **options)
