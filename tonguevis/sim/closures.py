"""A stop is a closure: at each consonant's closure the part of the tongue that makes it meets the palate.

The sensors say where the tongue is at a /t/ or /k/ closure, not where the tip or the dorsum around the sensor
touches: a tongue-tip coil sits some 10 mm behind the tip, and on the shared OSN12 /ta/ it stayed 1-4 mm under
the palate at the closures while the tip ahead of it made the closure; on the shared /ka/ 006 the dorsum coil was
2-3.5 mm under the speech's own roof at 3 of the 10 /k/ closures (the speaker holds the dorsum as high between
syllables, where it raised that roof).  With a palate, :func:`closure_contacts`
finds the productions' closures on the recording (:func:`tonguevis.preprocess.productions.find_productions`:
MVIEW's landmarks, the nucleus NONS-NOFFS around the maximum constriction, on the constricting articulator),
takes the constricting region of the tongue (the tip and blade ahead of TT; the dorsum about TD), and
during each closure pulls its :data:`CLOSURE_NODES` nodes that come nearest the palate onto it: springs
(:data:`tonguevis.sim.drive.PULL_STIFFNESS` times the sensors') towards where the region, carried by its sensor's
motion, meets the palate above it, eased in and out as a sensor returning from a dropout is
(:mod:`tonguevis.sim.dropouts`).  Everything else (the sensors, the modes, the contact) is as without them; the
motion's metadata say which nodes were pulled, when, and how far.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: How many of the region's nodes nearest the palate are pulled onto it at a closure (a closure seals across
#: the tongue's width, at /t/ around the tip's rim: more than one point).  With 3, the /t/ tip of the shared
#: 009 stayed 0.57 mm short at one closure once the drawn (warped) shape was kept out of the palate: the sides
#: of the blade, on the palate, held it down; with 5 the tip seals at both.
CLOSURE_NODES = 5
#: m: the constricting region about its sensor's node: the tip and blade ahead of TT (from REGION_BEHIND behind
#: it, within REGION_SIDE of it sideways); the dorsum within REGION_AROUND of TD or TB (front-back and sideways:
#: the dorsum around the coil, not the back of the tongue, which pulled from 10 mm away bent 1-1.3 mm into the
#: velum on the shared /ka/ 007).
REGION_BEHIND, REGION_SIDE, REGION_AROUND = 2e-3, 6e-3, 6e-3
#: s: a closure whose nucleus (NONS-NOFFS) was not found is taken as this either side of its maximum constriction.
HALF_CLOSURE = 0.03
#: m: the nodes pulled are no further than this from the palate where their sensor's motion carries them at the
#: maximum constriction (further: the recording does not show a closure there, and nothing is pulled).
CLOSURE_REACH = 6e-3
#: m: how far past the palate a closure's pull aims (the contact stops the tongue at the palate: it presses on
#: it); under :data:`tonguevis.sim.contact.CONFLICT_TOLERANCE`, so a pull never counts as a sensor above it.
PRESS = 0.4e-3
#: The tongue sensors whose closures are pressed: the tip's (its coil sits some 10 mm behind the tip that
#: closes) and the dorsum's (the roof where nothing was traced is the speech's own envelope, raised by the
#: dorsum's highest samples over the session: at a /k/ the coil can be millimetres under it).  The dorsum was
#: left to its own node on the velum while the estimated roof was raised narrowly along the sensors' path:
#: pulling the dorsum around it up then moved it 7-9 mm and pushed the back of the tongue 6 mm into the roof;
#: on the broad roof (:data:`tonguevis.sim.speaker_palate.ESTIMATE_RAISE_REACH`) the pulls are 2-5 mm and the
#: dorsum touches at 10 of 10 closures of the shared /ka/ 006 and 007 (7 and 8 without).
ARTICULATORS = ("TT", "TD")


@dataclass
class ClosureContacts:
    """Pulls drawing the constricting region onto the palate during the closures.

    nodes : (V,) mesh nodes; displacement : (F, V, 3) m, their targets' displacements from rest in the
    simulation's (jaw) frame, NaN where not held; info : what the metadata say.
    """

    nodes: np.ndarray
    displacement: np.ndarray
    info: dict


def closure_windows(recording, rest_interval, names) -> tuple[str | None, list[tuple[int, int, int]]]:
    """(articulator, [(first frame, frame of maximum constriction, last frame)] of each closure), found on the
    head-corrected ``recording`` (on its uniform grid) with the articulator tonguevis finds productions on; no
    closures when that articulator is not one of the driving tongue sensors ``names``."""
    from tonguevis.preprocess.correction import head_corrected
    from tonguevis.preprocess.productions import find_productions

    table = find_productions(head_corrected(recording, rest_interval=rest_interval), keep=None)
    articulator = table.articulator
    if articulator not in ARTICULATORS or articulator not in names:
        return None, []
    times = recording.times
    windows = []
    for production, landmarks in zip(table, table.landmarks or [None] * len(table)):
        peak = production.closure
        if not np.isfinite(peak):
            continue
        start = landmarks.times.get("nons", np.nan) if landmarks is not None else np.nan
        end = landmarks.times.get("noffs", np.nan) if landmarks is not None else np.nan
        start = start if np.isfinite(start) else peak - HALF_CLOSURE
        end = end if np.isfinite(end) else peak + HALF_CLOSURE
        first, middle, last = (int(np.clip(np.searchsorted(times, t), 0, len(times) - 1)) for t in (start, peak, end))
        windows.append((min(first, middle), middle, max(last, middle)))
    return articulator, windows


def constricting_region(model, node: int, articulator: str) -> np.ndarray:
    """(k,) the dorsal nodes that make a closure with ``articulator`` (whose sensor node is ``node``)."""
    points = model.mesh.points
    dorsal = np.asarray(model.dorsal_nodes)
    at = points[node]
    if articulator == "TT":  # the tip and blade: ahead of the sensor, about the midline it sits on
        keep = (points[dorsal, 0] >= at[0] - REGION_BEHIND) & (np.abs(points[dorsal, 1] - at[1]) <= REGION_SIDE)
    else:
        keep = ((np.abs(points[dorsal, 0] - at[0]) <= REGION_AROUND)
                & (np.abs(points[dorsal, 1] - at[1]) <= REGION_AROUND))
    return dorsal[keep]


def closure_contacts(recording, prep, model, contact) -> ClosureContacts | None:
    """The pulls of the closures of ``recording`` (on its uniform grid), or None when there are none.

    prep : the prepared targets (the sensors' displacements, the rest, the jaw's offsets); model : the model in
    the simulation's frame; contact : :func:`tonguevis.sim.palate_placement.contact_context`'s (the palate,
    its velum's lift per frame in ``jaw_offset``)."""
    from tonguevis.sim.contact import clearance_at
    from tonguevis.sim.dropouts import RAMP_S

    articulator, windows = closure_windows(recording, prep.rest.interval, prep.names)
    if not windows:
        return None
    k = prep.names.index(articulator)
    region = constricting_region(model, int(prep.nodes[k]), articulator)
    region = region[~np.isin(region, prep.nodes)]  # a sensor's node follows its sensor: not pulled as well
    if len(region) == 0:
        return None
    points = model.mesh.points
    offsets = contact["jaw_offset"]
    palate = contact["palate"]
    frames = prep.displacement.shape[0]
    chosen: dict[int, np.ndarray] = {}  # node -> (F, 3) target displacement, NaN where not held
    pulled, held = [], 0
    for first, middle, last in windows:
        carried = prep.displacement[middle, k]
        if not np.all(np.isfinite(carried)):
            continue
        gap, _ = clearance_at(palate, points[region] + carried, offsets[middle])
        order = np.argsort(np.where(np.isfinite(gap), gap, np.inf))[:CLOSURE_NODES]
        order = order[np.isfinite(gap[order]) & (gap[order] <= CLOSURE_REACH)]
        if len(order) == 0:
            continue
        # From a ramp before the closure (the virtual sensor's spring grows over it, as a sensor's does
        # coming back: tonguevis.sim.dropouts) the region follows its sensor, lifted towards the palate by a
        # share that reaches 1 at the closure's start.
        lead = max(1, int(round(RAMP_S * recording.rate)))
        span = np.arange(max(first - lead, 0), last + 1)
        share = np.clip((span - (first - lead)) / lead, 0.0, 1.0)
        share = share * share * (3.0 - 2.0 * share)
        moved = prep.displacement[span, k]  # the region carried by its sensor's motion, frame by frame
        ok = np.all(np.isfinite(moved), axis=1)
        span, moved, share = span[ok], moved[ok], share[ok]
        for node, reach in zip(region[order], gap[order]):
            where = points[node][None] + moved
            g, normal = clearance_at(palate, where[:, None], offsets[span])
            g, normal = g[:, 0], normal[:, 0]
            fine = np.isfinite(g)
            target = np.full((frames, 3), np.nan) if node not in chosen else chosen[node]
            # Up towards the palate by the share of the gap it had at the maximum constriction (the approach is
            # not dragged up), and at the closure PRESS into it: a stop presses the tongue on the palate, whose
            # contact keeps it out (the normal points down, away from the palate).
            pull = np.minimum((max(float(reach), 0.0) + PRESS) * share[fine], g[fine] + PRESS)
            target[span[fine]] = moved[fine] - normal[fine] * pull[:, None]
            chosen[int(node)] = target
            pulled.append(float(np.abs(pull).max()) if fine.any() else 0.0)
        held += len(span)
    if not chosen:
        return None
    nodes = np.array(sorted(chosen), dtype=np.int64)
    displacement = np.stack([chosen[n] for n in nodes], axis=1)
    info = {"articulator": articulator, "closures": len(windows), "nodes": nodes.tolist(),
            "maximum_constriction_frames": [int(middle) for _, middle, _ in windows],
            "closure_frames": [[int(first), int(last)] for first, _, last in windows],
            "frames_held": int(np.any(np.all(np.isfinite(displacement), axis=2), axis=1).sum()),
            "largest_pull_mm": 1e3 * max(pulled) if pulled else 0.0,
            "median_pull_mm": 1e3 * float(np.median(pulled)) if pulled else 0.0}
    return ClosureContacts(nodes, displacement, info)
