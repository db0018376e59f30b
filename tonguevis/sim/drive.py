"""What the frame loop is driven with: the measured sensors projected onto the tongue's own deformations,
dropouts bridged or handed over, and (with a palate) the tongue kept below it: :func:`drive_schedule`."""

from __future__ import annotations

import numpy as np


def drive_schedule(displacement: np.ndarray, rate: float, eigenvalues: np.ndarray, phi_s: np.ndarray,
                   sensor_stiffness: float | None, contact: dict | None = None):
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
    """
    from tonguevis.sim.constrained import compliant_targets, point_stiffness
    from tonguevis.sim.dropouts import RAMP_STIFFNESS, bridge_short_gaps, engagement, spring_compliance

    filled, bridged = bridge_short_gaps(displacement, rate)
    present = np.all(np.isfinite(filled), axis=2)
    k_ref = point_stiffness(eigenvalues, phi_s)
    base = 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * k_ref)
    weight, source = engagement(present, rate)
    anchored = filled[source, np.arange(filled.shape[1])[None, :]]  # a released sensor: its last measurement
    springs = spring_compliance(weight, base, RAMP_STIFFNESS * k_ref)
    info = {"bridged": bridged, "released": ~present, "weight": weight, "anchored": anchored}
    if contact is None:
        projected = compliant_targets(eigenvalues, phi_s, anchored, springs)
    else:
        from tonguevis.sim.contact import solve_contact

        solved = solve_contact(eigenvalues, contact["phi_nodes"], phi_s, anchored, springs, contact["points"],
                               contact["sensor_nodes"], contact["candidates"], contact["palate"],
                               contact["jaw_offset"], backend=contact.get("backend", "warp"))
        projected = solved.pop("targets")
        info.update(solved)
    acting = weight > 0
    targets = np.where(acting[:, :, None], projected, np.nan)
    compliance = np.where(acting, 0.0, np.inf)
    return targets, compliance, info
