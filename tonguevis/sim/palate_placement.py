"""The palate in the simulation's frame and the contact's glue around the frame loop: where the palate is placed
(:func:`place_palate`, :func:`placed_palate`), what the contact solve needs (:func:`contact_context`), sensors
touching it held to it (:func:`held_to_palate`), the shapes kept below it (:func:`keep_below_palate`) and the
contact report of a motion.  The solves themselves are :mod:`tonguevis.sim.contact`'s."""

from __future__ import annotations

import functools

import numpy as np

from tonguevis._logging import logger
from tonguevis.errors import SimulationError
from tonguevis.io.recording import Recording
from tonguevis.preprocess.rest import RestChoice
from tonguevis.preprocess.targets import PreparedTargets
from tonguevis.sim.model import TongueModel


def place_palate(palate, prep: PreparedTargets, quiet: bool = False, model: TongueModel | None = None,
                 speech_references: dict | None = None):
    """The palate in the simulation's frame, where the contact solve and the app's views use it:
    (surface at rest, velum lift (F,) m or None, info).

    palate : a :class:`~tonguevis.palate.PalateSurface`, a palate file or "generic"
    (:func:`tonguevis.palate.load_palate`).  A speaker's palate (the recording's frame,
    from ``tonguevis palate``) is carried onto the model by the recording's alignment ``prep.transform``
    and made whole from the speech (:func:`tonguevis.sim.speaker_palate.speaker_palate`): the traced part
    kept where it was traced (moved up by at most a coil's thickness), the rest estimated from the
    sensors and the tongue at rest, joined to the generic roof on the shipped tongue (``model`` None or it),
    the velum lifting frame by frame.  One whose metadata say ``frame == "model"`` (the generic one) is
    used as is, rigid (lift None).

    speech_references : the speech's head references where its head correction holds them
    (:func:`tonguevis.preprocess.correction.reference_pose`); a palate fitted from traces with the
    same references (``metadata["head_references"]``) is first carried into the speech's head
    frame by them (:func:`_by_head_references`).
    """
    from tonguevis.palate import load_palate

    from tonguevis.sim.placement import in_model_frame
    from tonguevis.sim.speaker_palate import speaker_palate

    palate = load_palate(palate)
    if palate.metadata.get("frame") == "model":  # the generic palate: placed with the model
        return (palate if model is None else in_model_frame(palate, model)), None, {}
    from tonguevis.palate import generic_palate

    palate = _by_head_references(palate, speech_references, quiet)
    t = prep.transform
    placed = palate.transformed(t.rotation, t.scale, t.translation)
    generic = None
    if model is None or shipped_tongue(model):  # the generic palate is our tongue's roof, not another mesh's
        generic = generic_palate() if model is None else in_model_frame(generic_palate(), model)
    # The sensors where the simulation has them (each on its node's rest, as drawn and held to the palate), in
    # the palate's (head) frame; without the model, where the alignment put them.
    at_rest = prep.aligned_rest if model is None else model.mesh.points[np.asarray(prep.nodes)]
    sensors = at_rest[None] + prep.displacement + prep.jaw_offset[:, None]
    rest = None if model is None else model.mesh.points[np.asarray(model.dorsal_nodes)]
    surface, lift, info = speaker_palate(placed, generic, sensors, rest)
    if not quiet:
        _say_palate(info)
    return surface, lift, info


def _say_palate(info: dict) -> None:
    """One line in the log: how the speaker's palate was completed and moved."""
    parts = [f"traced part kept ({100 * info['traced_share']:.0f} % of the roof)"]
    if info.get("traced_raised_mm", 0.0) > 0.05:
        parts.append(f"raised where the sensors went above it: up to {info['traced_raised_mm']:.1f} mm at x "
                     f"{info['traced_raised_at_mm'][0]:.0f} mm ({100 * info['traced_raised_share']:.0f} % of it over "
                     "0.5 mm)")
    if info.get("estimated_raised_mm", 0.0) > 0.05:
        parts.append(f"the estimated part raised up to {info['estimated_raised_mm']:.1f} mm to the speech")
    if info.get("velum_lifted_frames"):
        parts.append(f"the velum lifts up to {info['velum_lift_max_mm']:.1f} mm with the dorsum")
    logger.info("palate: %s", "; ".join(parts))


def _by_head_references(palate, speech_references: dict | None, quiet: bool = False):
    """``palate`` carried from its traces' head frame into the speech's by the head references both
    recorded (a rigid fit; said once with the references and the residual); as it is otherwise."""
    from tonguevis.preprocess.correction import register_references

    traced = palate.metadata.get("head_references")
    if not traced or not speech_references:
        return palate
    fit = register_references({n: np.asarray(v, dtype=float) for n, v in traced.items()}, speech_references)
    if fit is None:
        if not quiet:
            logger.warning("the palate's head references (%s) and the speech's (%s) share fewer than 3: not "
                           "registered by them", ", ".join(traced), ", ".join(speech_references))
        return palate
    rotation, translation, residual, names = fit
    moved = palate.transformed(rotation, 1.0, translation)
    moved.metadata["head_registration"] = {"references": names, "residual_mm": 1e3 * residual,
                                          "moved_mm": 1e3 * float(np.linalg.norm(translation))}
    if not quiet:
        logger.info("palate registered into the speech's head frame by the head references %s (moved %.1f mm, "
                    "residual %.2f mm)", ", ".join(names), 1e3 * float(np.linalg.norm(translation)), 1e3 * residual)
    return moved


def _speech_references(recording: Recording, prep: PreparedTargets, palate) -> dict:
    """The speech's head references in its head-corrected frame, when the palate has references to meet."""
    from tonguevis.palate import load_palate
    from tonguevis.preprocess.correction import head_corrected, reference_pose

    if not load_palate(palate).metadata.get("head_references"):
        return {}
    return reference_pose(head_corrected(recording, rest_interval=prep.rest_interval))


def shipped_tongue(model: TongueModel) -> bool:
    """Whether ``model`` is on the shipped tongue mesh (the one the generic palate belongs to), also
    placed in a speaker (:mod:`tonguevis.sim.placement`)."""
    from pathlib import Path

    from tonguevis.mesh.default import default_mesh_path
    from tonguevis.sim.placement import source_model

    model = source_model(model)

    source = model.mesh.metadata.get("source")
    try:
        return source is not None and Path(source).resolve() == default_mesh_path().resolve()
    except OSError:
        return False


def placed_palate(recording: Recording, palate, model: TongueModel | None = None, landmarks: str = "speaker",
                  rest: RestChoice | tuple[float, float] | None = None, smooth_window: int | None = None,
                  frame: str = "speaker", tongue_size: float | str | None = None):
    """The palate as :func:`simulate` places it for ``recording`` on ``model`` (unplaced, as given to
    :func:`simulate`): (surface at rest in the motion's ``frame``, velum lift (F,) m or None, info).

    For drawing a motion against its palate: pass the motion's landmarks, rest and frame
    (``motion.metadata["landmarks"]``, :func:`tonguevis.workflows.rest_of`,
    ``motion.metadata.get("frame", "model")``: motions saved before the speaker frame are in the
    model's; ``motion.metadata["fit"]["tongue_size"]``) so the alignment is the one the simulation used.
    """
    from tonguevis.sim.placement import targets_in_frame

    framed, prep, _ = targets_in_frame(recording, model or TongueModel.default(), frame, landmarks, rest,
                                       smooth_window, tongue_size=tongue_size)
    return place_palate(palate, prep, quiet=True, model=framed,  # the simulation said it once
                        speech_references=_speech_references(recording, prep, palate))


#: A rest whose tongue this share of the upper surface lies more than REST_CUT_DEPTH inside the palate is not
#: a rest with this palate (the tongue pressed into the vault: the generic tongue, placed there, crosses it).
REST_CUT_SHARE, REST_CUT_DEPTH = 0.2, 1e-3


class PalateCutsTheRest(SimulationError):
    """The palate cuts through the tongue at the rest chosen (another still stretch may do)."""


def contact_context(palate, prep, model, basis, recording) -> dict:
    """What the contact solve needs: the palate in the simulation's frame (at rest and its velum's lift per
    frame, in ``jaw_offset`` (F, 4): :func:`tonguevis.sim.contact.palate_offsets`), candidate nodes and their
    modes.  :class:`PalateCutsTheRest` when the palate cuts through the tongue at this rest."""
    from tonguevis.sim.contact import palate_offsets

    surface, lift, info = place_palate(palate, prep, model=model,
                                       speech_references=_speech_references(recording, prep, palate))
    candidates = np.asarray(model.dorsal_nodes)
    jaw = prep.jaw_offset if prep.jaw_offset is not None else np.zeros((recording.n_samples, 3))
    offsets = palate_offsets(jaw, lift)
    rest_frame = int(np.argmin(np.abs(recording.times - prep.rest.interval[0])))
    from tonguevis.sim.contact import clearance_at

    gap, _ = clearance_at(surface, model.mesh.points[candidates], offsets[min(rest_frame, len(offsets) - 1)])
    inside = np.nanmean(gap < -REST_CUT_DEPTH) if np.isfinite(gap).any() else 0.0
    if inside > REST_CUT_SHARE:
        raise PalateCutsTheRest(
            f"the palate cuts through the tongue at the rest {prep.rest.interval[0]:.2f}-{prep.rest.interval[1]:.2f} s "
            f"({100 * inside:.0f} % of its upper surface more than 1 mm inside it, up to {-1e3 * np.nanmin(gap):.0f} "
            "mm): the tongue is pressed up there", recording.metadata.get("file"))
    dofs = (3 * candidates[:, None] + np.arange(3)).ravel()
    return {"palate": surface, "candidates": candidates, "points": model.mesh.points,
            "phi_nodes": basis.phi[dofs].reshape(len(candidates), 3, -1), "sensor_nodes": np.asarray(prep.nodes),
            "jaw_offset": offsets, "lift": lift, "palate_info": info}


def keep_below_palate(q, contact, schedule, basis, phi_s, compliance: float, rotation_rows=None):
    """The dynamic shapes projected out of the palate where inertia carried them in (see contact.correct_frames).

    rotation_rows : (3k, m) the rotation matrix W's rows at the candidates (modal warping), or None (linear).
    The contact holds Φq below the palate; the shape drawn is R̃(Wq)Φq, which where a closure bends the
    dorsum hard lies further up (on the shared /ka/ 007 with the dorsum pulled onto the palate, one node behind
    TD 1.2 mm inside it where Φq was 0.1 mm under).  So the frames whose drawn shape goes in are corrected again,
    from the same dynamic shape, with the rotation's part R̃Φq - Φq of the last correction held fixed
    (:data:`WARP_ROUNDS` rounds)."""
    from tonguevis.sim.contact import clearance_at, correct_frames
    from tonguevis.sim.patch_contact import allowed_candidates

    cand, pts = contact["candidates"], contact["points"]
    allowed = allowed_candidates(contact, schedule["conflicts"], len(q), cand, sensors_free=False)
    solve = functools.partial(correct_frames, basis.eigenvalues, contact["phi_nodes"], phi_s, points=pts,
                              candidates=cand, palate=contact["palate"], compliance=compliance,
                              backend=contact.get("backend", "warp"))
    out, corrected = solve(q, jaw_offset=contact["jaw_offset"], allowed=allowed)
    if rotation_rows is None:
        return out, corrected
    from tonguevis.sim.contact import MARGIN

    k = len(cand)
    phi_flat = contact["phi_nodes"].reshape(3 * k, -1)
    offsets = contact["jaw_offset"]
    if contact.get("backend", "warp") == "warp":
        from tonguevis.sim.contact_kernel import Clearance
        from tonguevis.sim.kernels import rotate_accumulated_compiled as rotated

        query = Clearance(contact["palate"], pts[cand])
    else:
        from tonguevis.sim.rotation import rotate_accumulated as rotated

        def query(u, at):
            return clearance_at(contact["palate"], pts[cand][None] + u, at)

    def drawn(qs, frames):
        """(R̃Φq - Φq (f, k, 3), the least allowed clearance as drawn (f,)) of ``frames``."""
        linear = (qs @ phi_flat.T).reshape(len(qs), k, 3)
        shown = rotated((qs @ rotation_rows.T).reshape(len(qs), k, 3), linear)
        gap = query(shown, offsets[frames])[0]
        return shown - linear, np.nanmin(np.where(allowed[frames] & np.isfinite(gap), gap, np.inf), axis=1)

    redone: list = []
    for _ in range(WARP_ROUNDS):
        frames, shifts, least = [], [], []
        for start in range(0, len(out), 512):  # chunks: the drawn candidates are 24 bytes a node and frame
            part = np.arange(start, min(start + 512, len(out)))
            shift, low = drawn(out[part], part)
            inside = low < MARGIN - 1e-7
            frames.append(part[inside])
            shifts.append(shift[inside])
            least.append(low[inside])
        frames = np.concatenate(frames)
        if len(frames) == 0:
            break
        tried = solve(q[frames], jaw_offset=offsets[frames], allowed=allowed[frames], shift=np.concatenate(shifts))[0]
        better = drawn(tried, frames)[1] > np.concatenate(least)  # a correction that failed (the guard's q0): not taken
        out[frames[better]] = tried[better]
        redone.extend(frames[better].tolist())
    return out, np.union1d(corrected, np.asarray(redone, dtype=np.int64))


#: Rounds of correcting the drawn (warped) shape after the linear one (:func:`keep_below_palate`).
WARP_ROUNDS = 1


def contact_probe(contact, schedule, model):
    """What :func:`tonguevis.sim.figures.frame_figures` needs to measure contact, per chunk of frames.

    Every candidate node counts, also those around a sensor above the palate (the tongue drawn
    there is inside it): the figures say what the geometry is."""
    from tonguevis.sim.figures import ContactProbe

    cand, pts = contact["candidates"], contact["points"]
    return ContactProbe(pts, cand, contact["palate"], contact["jaw_offset"], model.surface_faces,
                        np.zeros((0, 2), dtype=np.int64), np.zeros((len(cand), 0), dtype=bool))


#: m (the speaker's): a sensor this close under the palate is taken to touch it.  The coil and its glue
#: lie between tongue and palate (an NDI Wave sensor is about 1 mm thick with its glue) and the Wave's
#: stated accuracy is 0.5 mm: a coil measured within 1 mm of the palate at a closure is pressed on it,
#: with the tongue around it touching.  Without this, of the frames with a sensor that close to the
#: speaker's palate, 7 of 387 (/ta/ 009) and 2 of 753 (/ka/ 006) showed no contact.
TOUCH_REACH = 1e-3


def held_to_palate(contact: dict, rest: np.ndarray, displacement: np.ndarray, reach: float,
                   names) -> tuple[np.ndarray, dict]:
    """The sensor displacements the tongue follows: those of a sensor within ``reach`` (m) below the
    palate moved up onto it, along the palate's normal; and what was moved, for the metadata.

    rest : (S, 3) the sensor nodes' rest positions (m, the simulation's frame).
    displacement : (F, S, 3) m, the measured sensors' displacements (NaN where not measured).
    Returns ((F, S, 3) displacements, {"reach_mm", "frames": {name: frames held}, "largest_move_mm"}).
    Sensors above the palate, far below it or outside its footprint are left as measured.
    """
    from tonguevis.sim.contact import MARGIN, clearance_at

    frames = displacement.shape[0]
    offsets = contact["jaw_offset"][:frames]
    gap, normal = clearance_at(contact["palate"], rest[None] + displacement, offsets)
    near = np.isfinite(gap) & (gap > MARGIN) & (gap <= reach)
    held = displacement.copy()
    first = gap.copy()
    for _ in range(2):  # onto the palate, the contact's margin below it (again: the palate is curved)
        held[near] -= normal[near] * (gap[near] - MARGIN)[:, None]  # the normal points down, away from the palate
        gap, normal = clearance_at(contact["palate"], rest[None] + held, offsets)
        near &= np.isfinite(gap)
    moved = np.linalg.norm(held - displacement, axis=2)  # never further than the reach (a steep velum's normals)
    far = near & (moved > reach)
    held[far] = displacement[far] + (held[far] - displacement[far]) * (reach / moved[far])[:, None]
    info = {"reach_mm": 1e3 * reach,
            "frames": {name: int(near[:, k].sum()) for k, name in enumerate(names) if near[:, k].any()},
            "largest_move_mm": float(1e3 * first[near].max()) if near.any() else 0.0}
    return held, info


def sensor_depth(contact, sensors: np.ndarray, cut: slice) -> np.ndarray:
    """(F, S) how far (m, >= 0) each sensor (F, S, 3, model frame, jaw's frame) lies above the palate;
    0 below it, NaN where not measured or no palate lies above."""
    from tonguevis.sim.contact import clearance_at

    gap, _ = clearance_at(contact["palate"], sensors, contact["jaw_offset"][cut])
    return np.where(np.isfinite(gap), np.maximum(0.0, -gap), np.nan)


def contact_report(pen, contact_area, contact, schedule, times, sensor_depth, names):
    """The contact figures for metadata, from the per-frame penetration (m) of the tongue's nodes,
    its contact area (m²) and the depth (F, S) m of each sensor above the palate.

    They say what the geometry says: a sensor above the palate is penetration (the tongue follows
    the sensor there), and a frame is in contact when the tongue touches, enters or presses on the
    palate, whatever made it."""
    above = np.nan_to_num(sensor_depth) > 0
    deepest_sensor = float(np.nanmax(sensor_depth)) if np.isfinite(sensor_depth).any() else 0.0
    touching = (contact_area > 0) | (pen > 0) | (schedule["active"][:len(pen)] > 0)  # touching, inside or pressed
    conflicts = sorted({s for _, s in schedule["conflicts"]})
    figures = {
        "penetration_max_mm": float(1e3 * max(pen.max() if len(pen) else 0.0, deepest_sensor)),
        "tongue_penetration_max_mm": float(1e3 * pen.max()) if len(pen) else 0.0,
        "sensor_penetration_max_mm": 1e3 * deepest_sensor,
        "sensors_above_palate": {name: {"frames": int(above[:, k].sum()),
                                        "deepest_mm": float(1e3 * np.nanmax(sensor_depth[:, k]))}
                                 for k, name in enumerate(names) if above[:, k].any()},
        "frames_in_contact": int(touching.sum()),
        "frames_with_contact_forces": int(np.sum(schedule["active"] > 0)),
        "frames_corrected_after_the_dynamics": int(len(schedule.get("corrected_frames", []))),
        "contact_area_max_mm2": float(1e6 * contact_area.max()) if len(contact_area) else 0.0,
        "conflicts": {"frames": len({f for f, _ in schedule["conflicts"]}),
                      "by_sensor_index": {int(s): sum(1 for _, t in schedule["conflicts"] if t == s) for s in conflicts},
                      "first_s": float(times[schedule["conflicts"][0][0]]) if schedule["conflicts"] else None},
        "palate": {k: v for k, v in contact["palate"].metadata.items()
                   if k in ("rms_m", "source", "frame", "kept", "joined", "min_bend_radius_m", "bend_radius_m",
                            "head_registration", "speaker_palate")},
        "palate_raised_mm": float(contact.get("palate_info", {}).get("traced_raised_mm", 0.0)),  # the traced part
        **({"sensors_held_to_palate": contact["held_to_palate"]} if "held_to_palate" in contact else {}),
        **({"closures": contact["closures"]} if "closures" in contact else {}),
    }
    return figures
