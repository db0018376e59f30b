"""What the frame loop is driven with: the measured sensors projected onto the tongue's own deformations,
dropouts bridged or handed over, and (with a palate) the tongue kept below it: :func:`drive_schedule`."""

from __future__ import annotations

import numpy as np


def drive_schedule(displacement: np.ndarray, rate: float, eigenvalues: np.ndarray, phi_s: np.ndarray,
                   sensor_stiffness: float | None, contact: dict | None = None, pulls: int = 0):
    """What the integrator is driven with: (targets (F, S, 3), compliance (F, S), info).

    The measured sensor displacements (F, S, 3; NaN = missing) are projected
    frame by frame onto the tongue's own deformations
    (:func:`tonguevis.sim.constrained.compliant_targets`: sensor springs of
    ``sensor_stiffness`` times the point stiffness; None keeps the
    measurements, the paper's hard constraints), which also predicts where a
    missing sensor's node goes.  Dropouts are bridged or handed over to that
    prediction (:mod:`tonguevis.sim.dropouts`).  The dynamic solve then holds
    the acting sensor nodes to these targets with hard multipliers: a spring
    in the dynamic solve itself would lag behind fast speech (the sensor
    node, a mass on a spring with the modes' damping, trailed a real /ta/ by
    up to 7 mm).  info: {"bridged": gaps interpolated, "released": (F, S)
    frames a sensor was missing after bridging}.  With ``contact`` (from
    :func:`contact_context`) the projection keeps the tongue below the palate
    (:func:`tonguevis.sim.contact.solve_contact`) and info adds the contact
    forces ("external", (F, m) modal) for the dynamic solve, "active" and "conflicts".

    pulls : the last rows of ``displacement`` and ``phi_s`` are not sensors but pulls (the closures' virtual
    sensors, :mod:`tonguevis.sim.closures`): springs :data:`PULL_STIFFNESS` times the sensors' in the
    projection, eased in and out as a sensor back from a dropout; their forces join ``info["external"]`` (the
    dynamic solve applies them, as the contact's: in the static limit it reproduces the projection) and only
    the S - pulls sensors' targets are returned (and ``weight``, ``anchored``, ``released`` of them); info adds
    "pull_targets" (F, pulls, 3), where the projection put the pulled nodes, and "pull_weight" (F, pulls).
    Pulls are forces, not constraints: held exactly beside a sensor's node, a pull made Newton run away.
    """
    from tonguevis.sim.constrained import compliant_targets, point_stiffness
    from tonguevis.sim.dropouts import RAMP_STIFFNESS, bridge_short_gaps, engagement, spring_compliance

    rows = displacement.shape[1]
    sensors = rows - pulls
    filled, bridged = bridge_short_gaps(displacement, rate)
    present = np.all(np.isfinite(filled), axis=2)
    k_ref = point_stiffness(eigenvalues, phi_s[:sensors])
    base = np.full(rows, 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * k_ref))
    if pulls:
        base[sensors:] = 1.0 / (PULL_STIFFNESS * (sensor_stiffness or DEFAULT_PULL_BASE) * k_ref)
    weight, source = engagement(present, rate)
    anchored = filled[source, np.arange(filled.shape[1])[None, :]]  # a released sensor: its last measurement
    springs = spring_compliance(weight, base, RAMP_STIFFNESS * k_ref)
    info = {"bridged": bridged, "released": ~present[:, :sensors], "weight": weight[:, :sensors],
            "anchored": anchored[:, :sensors]}
    if pulls and contact is not None:  # a pull held while it lets go must not end up deep in a moving palate
        anchored = _pulls_at_most_pressing(anchored, sensors, contact)
    if contact is None:
        projected = compliant_targets(eigenvalues, phi_s, anchored, springs)
    else:
        from tonguevis.sim.contact import solve_contact

        solved = solve_contact(eigenvalues, contact["phi_nodes"], phi_s, anchored, springs, contact["points"],
                               contact["sensor_nodes"], contact["candidates"], contact["palate"],
                               contact["jaw_offset"], backend=contact.get("backend", "warp"))
        projected = solved.pop("targets")
        info.update(solved)
    if pulls:  # each pull's spring force, f = (where it pulls - where the node is) / C, as a modal force
        stretch = np.nan_to_num(anchored[:, sensors:] - projected[:, sensors:])
        with np.errstate(divide="ignore", invalid="ignore"):
            force = np.where((weight[:, sensors:] > 0)[:, :, None], stretch / springs[:, sensors:, None], 0.0)
        pull = np.einsum("vcm,fvc->fm", phi_s[sensors:], np.nan_to_num(force, posinf=0.0, neginf=0.0))
        info["external"] = info.get("external", 0.0) + pull
        info["pull_force_max_n"] = float(np.abs(force).max()) if force.size else 0.0
        # where the projection put the pulled nodes, and how engaged each pull is: the closures' static shapes
        # (:func:`tonguevis.sim.simulate.static_at_closures`)
        info["pull_targets"], info["pull_weight"] = projected[:, sensors:], weight[:, sensors:]
        projected, weight = projected[:, :sensors], weight[:, :sensors]
    acting = weight > 0
    targets = np.where(acting[:, :, None], projected, np.nan)
    compliance = np.where(acting, 0.0, np.inf)
    return targets, compliance, info


#: A closure's pull (:mod:`tonguevis.sim.closures`) as a multiple of the sensors' springs: the palate stops the
#: tongue, and at a stop the tongue presses on it; ten times the sensors' brings the tip within a few tenths of
#: a millimetre of it on the real /ta/ (the contact keeps it out).
PULL_STIFFNESS = 30.0
#: The sensors' spring the pulls are a multiple of when the sensors are held exactly (hard constraints).
DEFAULT_PULL_BASE = 20.0


def _pulls_at_most_pressing(anchored: np.ndarray, sensors: int, contact: dict) -> np.ndarray:
    """``anchored`` (F, S, 3) with each pull's target (the rows from ``sensors`` on) moved back along the
    palate's normal to at most :data:`tonguevis.sim.closures.PRESS` inside it: a pull's target anchored while
    its spring lets go (a dropout's hand-over) stays where it was while the jaw carries the palate, and a target
    deeper than the sensors' tolerance would count as a sensor above the palate, whose neighbourhood the
    contact leaves free."""
    from tonguevis.sim.closures import PRESS
    from tonguevis.sim.contact import clearance_at

    out = np.array(anchored, copy=True)
    rest = contact["points"][contact["sensor_nodes"][sensors:]]
    gap, normal = clearance_at(contact["palate"], rest[None] + np.nan_to_num(out[:, sensors:]),
                               contact["jaw_offset"][:len(out)])
    deep = np.isfinite(gap) & (gap < -PRESS) & np.all(np.isfinite(out[:, sensors:]), axis=2)
    pulls = out[:, sensors:]
    pulls[deep] += normal[deep] * (-PRESS - gap[deep])[:, None]  # the normal points down, out of the palate
    return out
