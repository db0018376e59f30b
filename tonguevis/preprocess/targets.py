"""From a recording to the sensor targets that drive a tongue model (§3.1).

:func:`prepare_targets` chooses the rest interval (:func:`choose_rest_interval`),
removes head and jaw motion, takes the rest pose, fits the sensors' rest
positions onto the model by a similarity transform and picks each sensor's
node.  The simulation, the validation and every front end go through it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from tonguevis.errors import SimulationError
from tonguevis.io.recording import Recording
from tonguevis.preprocess._names import TONGUE
from tonguevis.preprocess.rest import RestChoice, choose_rest_interval

from tonguevis._logging import logger

TONGUE_SENSORS = TONGUE
LATERAL_SENSORS = ("TL", "TR")


@dataclass
class PreparedTargets:
    """Aligned sensor motion ready to drive a model.

    names : S driving sensors; nodes : (S,) their mesh nodes;
    displacement : (F, S, 3) sensor displacement from rest in the model frame (m), NaN = missing;
    transform : the similarity fit recording -> model; ignored : sensors without a node;
    rest : the :class:`RestChoice` (interval and how it was found);
    midsagittal : whether the fit kept the midsagittal plane;
    alignment_rms : RMS distance (m) between aligned rest sensors and their nodes before snapping.
    aligned_rest : (S, 3) rest positions of the sensors in the model frame (m).
    jaw_offset : (F, 3) the jaw's translation from its rest in the model frame (m), zeros
        without a JAW sensor: what carries the tongue (simulated in the jaw's frame)
        into the head's frame, where the palate is fixed.
    """

    names: list[str]
    nodes: np.ndarray
    displacement: np.ndarray
    transform: Any
    ignored: list[str]
    rest: RestChoice
    midsagittal: bool
    alignment_rms: float
    aligned_rest: np.ndarray
    jaw_offset: np.ndarray | None = None

    @property
    def rest_interval(self) -> tuple[float, float]:
        """(start_s, end_s) of the rest (``rest.interval``)."""
        return self.rest.interval


def driving_sensors(recording: Recording, model) -> list[str]:
    """The tongue sensors that drive ``model`` in :func:`prepare_targets` (working, with a landmark on it)."""
    present = [n for n in TONGUE_SENSORS if n in recording.sensors and recording.valid(n).any()]
    return [n for n in present if n in model.landmarks.sensors]


def prepare_targets(
    recording: Recording,
    model,
    landmarks: str = "speaker",
    rest: RestChoice | tuple[float, float] | None = None,
    smooth_window: int | None = None,
    transform=None,
) -> PreparedTargets:
    """Rest interval, head and jaw correction, rest pose, similarity fit, sensor-node choice (§3.1).

    model : a :class:`~tonguevis.sim.model.TongueModel` (its mesh and landmarks: anything with those will do;
        the simulation layer is above this one, so it is not imported here).

    rest : a :class:`RestChoice` (used as is), a (start_s, end_s) the user gave
        (checked), or None: :func:`choose_rest_interval` finds it (the longest
        still interval, else the stillest window) over the driving sensors.
    landmarks : "rule" keeps the model's placement-rule nodes (comparable
        across speakers, as the paper); "speaker" gives each sensor a dorsal-surface
        node near its own aligned rest position, a different node for each sensor
        (:func:`assign_sensor_nodes`).
    transform : a :class:`~tonguevis.preprocess.alignment.SimilarityTransform` (recording -> model) to use
        instead of fitting one, e.g. the identity for a model already placed in the speaker
        (:mod:`tonguevis.sim.placement`); ``alignment_rms`` is still measured against the rule nodes.
    """
    from tonguevis.preprocess.alignment import fit_similarity
    from tonguevis.preprocess.correction import correct_jaw, head_corrected
    from tonguevis.preprocess.filtering import smooth
    from tonguevis.preprocess.rest import rest_pose

    file = recording.metadata.get("file")
    if landmarks not in ("rule", "speaker"):
        raise SimulationError(f"landmarks must be 'rule' or 'speaker', got {landmarks!r}", file)
    present = working_tongue_sensors(recording)
    names = [n for n in present if n in model.landmarks.sensors]
    ignored = [n for n in present if n not in model.landmarks.sensors]
    if ignored:
        logger.warning("sensors %s have no landmark on the model and are ignored", ", ".join(ignored))
    if len(names) < 2:
        from tonguevis.io.sensor_map import how_to_map

        raise SimulationError(
            f"too few tongue sensors to drive the model: found {names or 'none'} of "
            f"{', '.join(TONGUE_SENSORS)} (recording sensors: {', '.join(recording.sensor_names)}); "
            + how_to_map(recording), file)
    if recording.metadata.get("frame") == "device":  # said once, plainly, by `tonguevis info` and the app
        logger.info("%s: positions in the device's frame (axes not stated): taken as x anterior, y left, z up",
                    file)
    if not isinstance(rest, RestChoice):
        rest = choose_rest_interval(recording, sensors=names, given=rest)
    rest_interval = rest.interval
    rec = head_corrected(recording, rest_interval=rest_interval)
    jaw_moved = None
    if "JAW" in rec.sensors:
        jaw = rec.sensors["JAW"]
        jaw_moved = jaw - rest_pose(rec, rest_interval, sensors=["JAW"])["JAW"]
        rec = correct_jaw(rec, rest_interval=rest_interval)
    if smooth_window:
        rec = smooth(rec, window=smooth_window, sensors=names)
    rest_positions = rest_pose(rec, rest_interval, sensors=names)
    source = np.array([rest_positions[n] for n in names])
    rule_nodes = np.array([int(model.landmarks.sensors[n]) for n in names])
    target = model.mesh.points[rule_nodes]
    midsagittal = not any(n in LATERAL_SENSORS for n in names)
    if not midsagittal and len(names) < 3:
        raise SimulationError(f"a 3-D alignment needs at least 3 tongue sensors, got {names}", file)
    if transform is None:
        transform = fit_similarity(source, target, midsagittal=midsagittal)
    aligned_rest = transform.apply(source)
    alignment_rms = float(np.sqrt(np.mean(np.sum((aligned_rest - target) ** 2, axis=1))))
    if landmarks == "speaker":
        nodes = assign_sensor_nodes(aligned_rest, model.mesh.points, model.dorsal_nodes)
    else:
        nodes = rule_nodes
    positions = np.stack([rec.sensors[n] for n in names], axis=1)  # (F, S, 3)
    # Displacement from rest, rotated and scaled into the model frame.
    displacement = transform.scale * (positions - source[None]) @ transform.rotation.T
    jaw_offset = np.zeros((recording.n_samples, 3))
    if jaw_moved is not None:
        jaw_offset = _filled(transform.scale * jaw_moved @ transform.rotation.T)
    return PreparedTargets(
        names, nodes, displacement, transform, ignored, rest, midsagittal, alignment_rms, aligned_rest, jaw_offset
    )


def assign_sensor_nodes(positions: np.ndarray, points: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """(S,) distinct node ids, one per sensor, from ``candidates``, nearest as a whole.

    positions : (S, 3) sensors' aligned rest positions (m); points : (n, 3) mesh nodes (m);
    candidates : (C,) node ids allowed (the dorsal surface), C >= S.

    An assignment (scipy's ``linear_sum_assignment``) minimising the sum of the
    squared sensor-node distances over one-to-one choices: where each sensor's
    own nearest node differs, that is what it gets; where two sensors share a
    nearest node (sensors closer together than the mesh's edges, or a mesh in a
    coarse region), the pair takes the two nodes that cost least together,
    never one node for two sensors (which the simulation cannot drive).
    """
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    candidates = np.asarray(candidates, dtype=np.int64).reshape(-1)
    if candidates.size < len(positions):
        raise SimulationError(f"{len(positions)} sensors need as many distinct surface nodes, the mesh has "
                              f"{candidates.size}")
    # Only the few nearest candidates of each sensor can win: keep the cost matrix small.
    k = min(candidates.size, 4 * len(positions))
    _, near = cKDTree(points[candidates]).query(positions, k=k)
    pool = np.unique(near)
    cost = np.sum((positions[:, None, :] - points[candidates[pool]][None]) ** 2, axis=2)
    rows, cols = linear_sum_assignment(cost)
    nodes = np.empty(len(positions), dtype=np.int64)
    nodes[rows] = candidates[pool[cols]]
    return nodes


def working_tongue_sensors(recording: Recording) -> list[str]:
    """The tongue sensors of ``recording`` that hold at least one valid sample, in canonical order.

    A coil that never worked (every sample NaN, e.g. a whole NDI Wave column of
    bad status) is left out with a warning: it has no rest position to align
    and nothing to drive, and the others can drive the model without it.
    """
    present = [n for n in TONGUE_SENSORS if n in recording.sensors]
    dead = [n for n in present if not recording.valid(n).any()]
    if dead:
        logger.warning("%s: %s %s no valid sample in the whole recording and %s left out",
                       recording.metadata.get("file", "recording"), ", ".join(dead),
                       "has" if len(dead) == 1 else "have", "is" if len(dead) == 1 else "are")
    return [n for n in present if n not in dead]


def _filled(x: np.ndarray) -> np.ndarray:
    """(F, 3) with missing samples interpolated linearly in time (held at the ends; zeros if none valid)."""
    ok = np.all(np.isfinite(x), axis=1)
    if ok.all() or not ok.any():
        return np.where(ok[:, None], x, 0.0)
    idx = np.arange(len(x))
    return np.column_stack([np.interp(idx, idx[ok], x[ok, k]) for k in range(3)])
