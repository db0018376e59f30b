#!/usr/bin/env python
"""Why the model lost to interpolation on real recordings: one candidate change at a time, measured.

For every real recording in ../shared/data/ema with enough tongue sensors
(Opti-Speech /ta/ and two /ka/, the Haskins sentence; skipped with a note when
../shared is absent), one row per candidate:

* **full pipeline** rows run :func:`tonguevis.analysis.validate` (dynamic,
  warped, ``quasi_static=False``): the paper's hard constraints with 100 and
  200 modes, with the placement-rule landmarks and with the mesh floor
  anchored; the default sensor stiffness κ (targets projected onto the
  tongue's own deformations, then held exactly) at κ = 5 ... 80; κ = 20 with
  200 modes, with ν = 0.45 and with half and double the Rayleigh damping;
  on Haskins also κ = 20 without the jaw correction.
* **spring in the dynamic solve**: the measured targets held by springs of
  κ = 20 inside the Newmark solve itself (the integrator's ``compliance=``),
  instead of being projected first; same leave-one-out, dynamic and warped.
* **linear quasi-static probe** rows (labelled so): a frame-by-frame linear
  static solve min ½qᵀΛq + Σ|Φ_s q − c|²/(2C) (C = 0 hard), fast enough to
  screen changes the library does not implement: sensor patches instead of
  single nodes, a linearised volume constraint, a non-rigid fit of the mesh to
  the speaker's rest layout, the stiffness chosen by marginal likelihood, and
  an oracle affine regression (a bound, not a predictor).  Probe rows are
  comparable with the probe's own "hard" and "κ = 20" rows, not exactly with
  the full pipeline's.

Scores: leave-one-sensor-out held-out RMSE (mm) and r of the model and of the
kinematic RBF baseline, per sensor and their mean; and from the run with every
sensor driving: far-field amplification (largest node displacement over the
largest sensor displacement, overall and per-frame max), largest volume change,
sensor misfit (RMS and max), recovered and flagged frames, cost in seconds.

``--json-dir`` keeps the rows as ``fidelity.json`` (summary scores only; keep it
outside the repository); ``--out`` writes the Markdown tables that
``scripts/validate_all.py`` embeds in docs/validation.md.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
#: (path under ../shared/data, sensor map, short name)
RECORDINGS = [
    ("ema/optispeech/009_OSN12_Tah_withFb_natural_HR.tsv", None, "/ta/ 009"),
    ("ema/optispeech/006_OSN12_Kah_nofb_natural_take2_HR.tsv", None, "/ka/ 006"),
    ("ema/optispeech/007_OSN12_Kah_withFb_natural_HR.tsv", None, "/ka/ 007"),
    ("ema/mview/F01_B01_S01_R01_N.mat", "haskins", "Haskins"),
]
KAPPAS = (5.0, 10.0, 20.0, 40.0, 80.0)
DEFAULT_KAPPA = 20.0
FLOOR_SHARE = 0.15  # floor anchors: the inferior surface nodes in the lowest 15 % of the mesh height
PATCHES_M = (0.003, 0.005, 0.008)
NOISE_WINDOW_S = 0.07  # sensor noise: residual of a local cubic over 70 ms (speech is smooth at that scale)

logger = logging.getLogger("tonguevis")


# --------------------------------------------------------------------------- rows
def _mean(values):
    vals = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.mean(vals)) if vals else float("nan")


def make_row(recording, candidate, kind, sensors, plaus=None, recovered=None, flagged=None,
             simulate_s=None, row_s=None, note=""):
    """One table row. sensors: name -> {model_rmse_mm, model_corr, kinematic_rmse_mm, kinematic_corr}."""
    plaus = plaus or {}
    return {
        "recording": recording, "candidate": candidate, "kind": kind,
        "model_rmse_mm": _mean(s["model_rmse_mm"] for s in sensors.values()),
        "model_corr": _mean(s["model_corr"] for s in sensors.values()),
        "kinematic_rmse_mm": _mean(s["kinematic_rmse_mm"] for s in sensors.values()),
        "kinematic_corr": _mean(s["kinematic_corr"] for s in sensors.values()),
        "sensors": {n: {k: float(v) for k, v in s.items()} for n, s in sensors.items()},
        "amplification": plaus.get("amplification"),
        "amplification_frame_max": plaus.get("amplification_frame_max"),
        "volume_change_max_percent": plaus.get("volume_change_max_percent"),
        "sensor_misfit_rms_mm": plaus.get("sensor_misfit_rms_mm"),
        "sensor_misfit_max_mm": plaus.get("sensor_misfit_max_mm"),
        "recovered_frames": recovered, "flagged_frames": flagged,
        "simulate_s": simulate_s, "row_s": row_s, "note": note,
    }


# --------------------------------------------------------------------------- full pipeline
def in_memory(model, modes=100):
    """``model`` with its modes solved now and kept in memory only (a study variant must not fill the disk cache)."""
    model.basis(modes, cache=False)
    return model


def with_material(model, **changes):
    """The same mesh and landmarks with other material constants."""
    from tonguevis.sim import TongueModel

    return in_memory(TongueModel(model.mesh, model.landmarks, replace(model.material, **changes)))


def floor_anchored(model):
    """The model with every inferior-surface node in the lowest FLOOR_SHARE of its height fixed too."""
    from tonguevis.mesh import inferior_surface_nodes
    from tonguevis.sim import TongueModel

    floor = inferior_surface_nodes(model.mesh)
    z = model.mesh.points[:, 2]
    low = floor[z[floor] < z.min() + FLOOR_SHARE * (z.max() - z.min())]
    landmarks = SimpleNamespace(sensors=model.landmarks.sensors, anchors=np.unique(np.r_[model.anchors, low]))
    return in_memory(TongueModel(model.mesh, landmarks, model.material)), len(low)


def without_jaw(recording):
    """The recording without its jaw channel (so no jaw correction)."""
    return recording.with_sensors({n: v for n, v in recording.sensors.items() if n != "JAW"},
                                  orientations={n: v for n, v in recording.orientations.items() if n != "JAW"})


def variants(model) -> dict:
    """The models the full-pipeline rows need besides ``model`` (built once, modes solved in memory)."""
    m = model.material
    floor_model, n_floor = floor_anchored(model)
    return {"floor": floor_model, "n_floor": n_floor, "nu": with_material(model, poisson=0.45),
            "damping/2": with_material(model, alpha=m.alpha / 2, beta=m.beta / 2),
            "damping*2": with_material(model, alpha=m.alpha * 2, beta=m.beta * 2)}


def full_candidates(model, var, recording):
    """[(label, model, recording, validate kwargs, note)] of the full-pipeline rows; var: :func:`variants`."""
    floor_model, n_floor = var["floor"], var["n_floor"]
    out = [
        ("paper: hard, 100 modes", model, recording, dict(sensor_stiffness=None), "the paper's setting"),
        ("hard, 200 modes", model, recording, dict(sensor_stiffness=None, modes=200), ""),
        ("hard, rule landmarks", model, recording, dict(sensor_stiffness=None, landmarks="rule"),
         "the paper's placement rule instead of the speaker's layout"),
        ("hard, floor anchored", floor_model, recording, dict(sensor_stiffness=None),
         f"{len(model.anchors)} anchors + {n_floor} floor nodes"),
    ]
    out += [(f"κ = {k:g}" + (" (default)" if k == DEFAULT_KAPPA else ""), model, recording,
             dict(sensor_stiffness=k), "") for k in KAPPAS]
    m = model.material
    out += [
        ("κ = 20, 200 modes", model, recording, dict(sensor_stiffness=DEFAULT_KAPPA, modes=200), ""),
        ("κ = 20, ν = 0.45", var["nu"], recording, dict(sensor_stiffness=DEFAULT_KAPPA), ""),
        ("κ = 20, damping ×½", var["damping/2"], recording,
         dict(sensor_stiffness=DEFAULT_KAPPA), f"α = {m.alpha / 2:g}, β = {m.beta / 2:g}"),
        ("κ = 20, damping ×2", var["damping*2"], recording,
         dict(sensor_stiffness=DEFAULT_KAPPA), f"α = {m.alpha * 2:g}, β = {m.beta * 2:g}"),
    ]
    if "JAW" in recording.sensors:
        out.append(("κ = 20, no jaw correction", model, without_jaw(recording), dict(sensor_stiffness=DEFAULT_KAPPA),
                    "the JAW channel dropped"))
    return out


def full_row(name, label, model, recording, kwargs, note):
    from tonguevis.analysis.validation import validate
    from tonguevis.sim import simulate

    t0 = time.perf_counter()
    # The model frame, as the probes' prepare_targets rows (the library's default is the speaker's since
    # tonguevis.sim.placement): the study's figures stay comparable with each other and its history.
    kwargs = {"frame": "model", **kwargs}
    result = validate(recording, model, quasi_static=False, **kwargs)
    row_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    simulate(recording, model, **kwargs)
    sim_s = time.perf_counter() - t0
    rec = result.recording
    sensors = {n: {k: s[k] for k in ("model_rmse_mm", "model_corr", "kinematic_rmse_mm", "kinematic_corr")}
               for n, s in result.sensors.items()}
    return make_row(name, label, "full pipeline", sensors, rec["plausibility"], len(rec["recovered_frames"]),
                    len(rec["implausible_frames"]), sim_s, row_s + sim_s, note)


# --------------------------------------------------------------------------- spring in the dynamic solve
def spring_in_dynamics_row(name, model, recording, kappa=DEFAULT_KAPPA, modes=100, landmarks="speaker"):
    """Leave-one-out with the measured targets held by springs inside the Newmark solve.

    The dropouts are handled as the library does for hard constraints (bridged,
    handed over to the model's prediction); every acting sensor then gets the
    compliance 1/(κ k_ref) in the dynamic solve itself.
    """
    from tonguevis.analysis.kinematic import interpolation_weights
    from tonguevis.analysis.validation_scores import trajectory_scores
    from tonguevis.preprocess.targets import prepare_targets
    from tonguevis.sim.constrained import point_stiffness
    from tonguevis.sim.newmark import NewmarkSettings
    from tonguevis.sim.newmark_kernel import integrate_compiled
    from tonguevis.sim.plausibility import plausibility_figures
    from tonguevis.sim.rotation import rotate_accumulated
    from tonguevis.sim.simulate import drive_schedule

    t_row = time.perf_counter()
    prep = prepare_targets(recording, model, landmarks, None)
    basis = model.basis(modes)
    w_full = model.rotation_matrix(basis)
    nodes = np.asarray(prep.nodes)
    s = len(nodes)
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    phi_s = basis.phi[dofs].reshape(s, 3, -1)
    w_s = w_full[dofs].reshape(s, 3, -1)
    spring = 1.0 / (kappa * point_stiffness(basis.eigenvalues, phi_s))
    trials, comps = [], []
    for h in range(-1, s):  # -1: every sensor driving
        disp = prep.displacement.copy()
        if h >= 0:
            disp[:, h] = np.nan
        targets, comp, _ = drive_schedule(disp, recording.rate, basis.eigenvalues, phi_s, None)
        trials.append(targets)
        comps.append(np.where(np.isfinite(comp), spring, np.inf))
    settings = NewmarkSettings(dt=1.0 / recording.rate, alpha=model.material.alpha, beta=model.material.beta)
    t0 = time.perf_counter()
    full = integrate_compiled(basis.eigenvalues, phi_s, w_s, trials[0], settings, compliance=comps[0])
    sim_s = time.perf_counter() - t0
    runs = integrate_compiled(basis.eigenvalues, phi_s, w_s, np.stack(trials[1:]), settings,
                              compliance=np.stack(comps[1:]))
    disp_all = model.displacements(full.q, warping=True)
    volume = model.volume_change(disp_all)
    sensor_disp = rotate_accumulated(np.einsum("scm,fm->fsc", w_s, full.q), np.einsum("scm,fm->fsc", phi_s, full.q))
    misfit = np.linalg.norm(sensor_disp - prep.displacement, axis=2)
    plaus, absurd = plausibility_figures(disp_all, prep.displacement, volume, misfit)
    sensors = {}
    for h, name_h in enumerate(prep.names):
        keep = [k for k in range(s) if k != h]
        rows = slice(3 * nodes[h], 3 * nodes[h] + 3)
        q = runs[h].q
        pred = rotate_accumulated(q @ w_full[rows].T, q @ basis.phi[rows].T)
        weights = interpolation_weights(prep.aligned_rest[keep], prep.aligned_rest[h][None])[0]
        kin = np.einsum("n,fnc->fc", weights, prep.displacement[:, keep])
        measured = prep.displacement[:, h]
        ok = np.all(np.isfinite(measured), axis=1) & np.all(np.isfinite(pred), axis=1) & np.all(np.isfinite(kin), axis=1)
        a, b = trajectory_scores(measured[ok], pred[ok]), trajectory_scores(measured[ok], kin[ok])
        sensors[name_h] = {"model_rmse_mm": a["rmse_mm"], "model_corr": a["corr"],
                           "kinematic_rmse_mm": b["rmse_mm"], "kinematic_corr": b["corr"]}
    return make_row(name, f"spring in the dynamic solve, κ = {kappa:g}", "dynamic spring", sensors, plaus,
                    int(full.recovered.sum()), len(absurd), sim_s, time.perf_counter() - t_row,
                    "raw targets held by springs in the Newmark solve (no projection)")


# --------------------------------------------------------------------------- linear quasi-static probe
def sensor_rows(model, phi, nodes, patch_radius=0.0):
    """(S, 3, m) rows of Φ measured at each sensor: its node, or a Gaussian-weighted mean of the
    surface nodes within ``patch_radius`` (m) of it (σ = radius / 2): a coil glued over a patch."""
    pts = model.mesh.points
    surface = np.unique(model.surface_faces)
    out = np.zeros((len(nodes), 3, phi.shape[1]))
    for k, node in enumerate(nodes):
        if patch_radius <= 0:
            out[k] = phi[3 * node:3 * node + 3]
            continue
        d = np.linalg.norm(pts[surface] - pts[node], axis=1)
        near, dist = surface[d <= patch_radius], d[d <= patch_radius]
        w = np.exp(-0.5 * (dist / (patch_radius / 2)) ** 2)
        for node_j, w_j in zip(near, w / w.sum()):
            out[k] += w_j * phi[3 * node_j:3 * node_j + 3]
    return out


def static_solve(lam, rows, c, spring=None, extra=None):
    """q (F, m) minimising ½qᵀΛq + (k/2)|Φ_s q − c|² per frame (hard when ``spring`` k is None),
    with ``extra`` (r, m) hard linear constraints G q = 0.  rows (S, 3, m); c (F, S, 3)."""
    n_s, m = rows.shape[0], len(lam)
    p = rows.reshape(3 * n_s, m)
    rhs = c.reshape(len(c), 3 * n_s).T
    if extra is not None:
        p = np.vstack([p, extra])
        rhs = np.vstack([rhs, np.zeros((len(extra), rhs.shape[1]))])
    gram = (p / lam) @ p.T
    if spring is not None:
        gram = gram + np.diag(np.r_[np.full(3 * n_s, 1.0 / spring), np.zeros(len(p) - 3 * n_s)])
    if np.linalg.cond(gram) > 1e14:
        mult = np.linalg.lstsq(gram, rhs, rcond=None)[0]
    else:
        mult = np.linalg.solve(gram, rhs)
    return ((p.T @ mult) / lam[:, None]).T


def volume_gradient(model):
    """(3n,) dV/du of the enclosed volume at rest (the surface flux form)."""
    pts, faces = model.mesh.points, model.surface_faces
    grad = np.zeros_like(pts)
    p0, p1, p2 = (pts[faces[:, k]] for k in range(3))
    np.add.at(grad, faces[:, 0], np.cross(p1, p2) / 6)
    np.add.at(grad, faces[:, 1], np.cross(p2, p0) / 6)
    np.add.at(grad, faces[:, 2], np.cross(p0, p1) / 6)
    return grad.ravel()


def ml_spring(lam, rows, c, noise=None):
    """Type-II maximum likelihood of the spring k = s²/σ² for c_f ~ N(0, s² Φ_sΛ⁻¹Φ_sᵀ + σ² I), frames
    independent; σ fixed at ``noise`` (m) when given, else fitted too.  Returns k (N/m)."""
    from scipy.optimize import minimize, minimize_scalar

    p = rows.reshape(-1, len(lam))
    ev, vec = np.linalg.eigh((p / lam) @ p.T)
    ev = np.maximum(ev, 0.0)
    power = np.mean((c.reshape(len(c), -1) @ vec) ** 2, axis=0)
    if noise is not None:
        n2 = noise ** 2
        nll = lambda x: np.sum(np.log(np.exp(x) * ev + n2) + power / (np.exp(x) * ev + n2))  # noqa: E731
        r = minimize_scalar(nll, bounds=(np.log(1e-12), np.log(1e3)), method="bounded")
        return float(np.exp(r.x) / n2)

    def nll2(x):
        v = np.exp(x[0]) * ev + np.exp(x[1])
        return np.sum(np.log(v) + power / v)

    x0 = [np.log(np.mean(power) / max(np.mean(ev), 1e-30)), np.log(1e-8)]
    r = minimize(nll2, x0, method="Nelder-Mead", options=dict(xatol=1e-4, fatol=1e-6, maxiter=2000))
    return float(np.exp(r.x[0] - r.x[1]))


def sensor_noise(displacement, rate):
    """RMS (m, per coordinate) of the residual after a local cubic fit over NOISE_WINDOW_S."""
    from tonguevis.preprocess._localpoly import savgol

    window = max(int(round(NOISE_WINDOW_S * rate)) | 1, 5)
    return float(np.sqrt(np.nanmean((displacement - savgol(displacement, window, 3)) ** 2)))


class Probe:
    """The linear quasi-static leave-one-out of one prepared recording, on the frames where every sensor is valid."""

    def __init__(self, model, prep, modes=100):
        from tonguevis.sim.constrained import point_stiffness

        self.model, self.prep = model, prep
        self.basis = model.basis(modes)
        self.lam, self.phi = self.basis.eigenvalues, self.basis.phi
        ok = np.all(np.isfinite(prep.displacement), axis=(1, 2))
        self.c = prep.displacement[ok]
        self.names = prep.names
        self.point_rows = sensor_rows(model, self.phi, prep.nodes)
        self.k_ref = point_stiffness(self.lam, self.point_rows)

    def kinematic(self, h):
        from tonguevis.analysis.kinematic import interpolation_weights

        keep = [k for k in range(len(self.names)) if k != h]
        w = interpolation_weights(self.prep.aligned_rest[keep], self.prep.aligned_rest[h][None])[0]
        return np.einsum("n,fnc->fc", w, self.c[:, keep])

    def row(self, name, label, rows=None, kappa=None, spring_of=None, extra=None, note=""):
        """kappa: κ (× the point stiffness of ``rows``), None = hard; spring_of(rows, c) -> k per trial instead."""
        from tonguevis.analysis.validation_scores import trajectory_scores
        from tonguevis.sim.constrained import point_stiffness
        from tonguevis.sim.plausibility import plausibility_figures

        t0 = time.perf_counter()
        rows = self.point_rows if rows is None else rows
        spring = None if kappa is None else kappa * point_stiffness(self.lam, rows)
        s = len(self.names)
        springs = []
        k_all = spring_of(rows, self.c) if spring_of else spring
        q = static_solve(self.lam, rows, self.c, k_all, extra)
        disp = (q @ self.phi.T).reshape(len(q), -1, 3)
        volume = self.model.volume_change(disp, backend="numpy")
        misfit = np.linalg.norm(np.einsum("scm,fm->fsc", rows, q) - self.c, axis=2)
        plaus, absurd = plausibility_figures(disp, self.c, volume, misfit)
        del disp
        sensors = {}
        for h in range(s):
            keep = [k for k in range(s) if k != h]
            k_h = spring_of(rows[keep], self.c[:, keep]) if spring_of else spring
            springs.append(k_h)
            qh = static_solve(self.lam, rows[keep], self.c[:, keep], k_h, extra)
            pred = np.einsum("cm,fm->fc", rows[h], qh)
            a, b = trajectory_scores(self.c[:, h], pred), trajectory_scores(self.c[:, h], self.kinematic(h))
            sensors[self.names[h]] = {"model_rmse_mm": a["rmse_mm"], "model_corr": a["corr"],
                                      "kinematic_rmse_mm": b["rmse_mm"], "kinematic_corr": b["corr"]}
        row_extra = {}
        if spring_of:
            kap = np.array(springs) / self.k_ref
            row_extra = {"kappa_chosen": [float(kap.min()), float(kap.max()), float(k_all / self.k_ref)]}
            note = (note + "; " if note else "") + (f"κ chosen per trial {kap.min():.2g} … {kap.max():.2g} "
                                                    f"(all sensors: {k_all / self.k_ref:.2g})")
        return {**make_row(name, f"probe: {label}", "linear quasi-static probe", sensors, plaus, 0, len(absurd),
                           None, time.perf_counter() - t0, note), **row_extra}

    def oracle_row(self, name):
        """Each held-out sensor regressed affinely on the drivers' displacements, fitted in-sample: a bound."""
        from tonguevis.analysis.validation_scores import trajectory_scores

        t0 = time.perf_counter()
        s = len(self.names)
        sensors = {}
        for h in range(s):
            keep = [k for k in range(s) if k != h]
            x = np.c_[self.c[:, keep].reshape(len(self.c), -1), np.ones(len(self.c))]
            coef = np.linalg.lstsq(x, self.c[:, h], rcond=None)[0]
            a = trajectory_scores(self.c[:, h], x @ coef)
            b = trajectory_scores(self.c[:, h], self.kinematic(h))
            sensors[self.names[h]] = {"model_rmse_mm": a["rmse_mm"], "model_corr": a["corr"],
                                      "kinematic_rmse_mm": b["rmse_mm"], "kinematic_corr": b["corr"]}
        return make_row(name, "probe: oracle affine regression (in-sample)", "linear quasi-static probe", sensors,
                        row_s=time.perf_counter() - t0,
                        note="held-out sensor fitted on the drivers with its own motion: a bound, not a predictor")


def rest_fitted(model, prep, modes=100):
    """The mesh deformed (hard linear static solve) so the sensor nodes sit on the speaker's aligned rest
    positions, as a new reference configuration: (model, RMS offset removed mm, smallest tet volume ratio)."""
    from tonguevis.mesh.tetmesh import TetMesh, signed_tet_volumes
    from tonguevis.sim import TongueModel

    basis = model.basis(modes)
    offset = prep.aligned_rest - model.mesh.points[prep.nodes]
    q = static_solve(basis.eigenvalues, sensor_rows(model, basis.phi, prep.nodes), offset[None])
    moved = model.mesh.points + (q @ basis.phi.T).reshape(-1, 3)
    mesh = TetMesh(moved, model.mesh.tets, dict(model.mesh.metadata))
    ratio = float((signed_tet_volumes(moved, mesh.tets) / signed_tet_volumes(model.mesh.points, mesh.tets)).min())
    return (in_memory(TongueModel(mesh, model.landmarks, model.material), modes),
            float(1e3 * np.sqrt(np.mean(np.sum(offset ** 2, axis=1)))), ratio)


def probe_rows(name, model, recording, modes=100):
    from tonguevis.preprocess.targets import prepare_targets

    prep = prepare_targets(recording, model, "speaker", None)
    probe = Probe(model, prep, modes)
    noise = sensor_noise(prep.displacement, recording.rate)
    out = [probe.row(name, "hard"), probe.row(name, "κ = 20", kappa=DEFAULT_KAPPA)]
    for radius in PATCHES_M:
        rows = sensor_rows(model, probe.phi, prep.nodes, radius)
        out.append(probe.row(name, f"hard, {1e3 * radius:g} mm sensor patches", rows=rows))
    vol = (volume_gradient(model) @ probe.phi)[None]
    out.append(probe.row(name, "hard + volume constraint", extra=vol, note="linearised: dV/du · Φ q = 0"))
    out.append(probe.row(name, "κ = 20 + volume constraint", kappa=DEFAULT_KAPPA, extra=vol))
    out.append(probe.row(name, "ML stiffness (noise fitted)", spring_of=lambda r, c: ml_spring(probe.lam, r, c)))
    out.append(probe.row(name, "ML stiffness (noise = measured)",
                         spring_of=lambda r, c: ml_spring(probe.lam, r, c, noise),
                         note=f"measured sensor noise {1e3 * noise:.3f} mm"))
    fitted, offset_mm, ratio = rest_fitted(model, prep, modes)
    fit = Probe(fitted, prep, modes)
    fit_note = f"mesh moved {offset_mm:.2f} mm RMS at the sensors; smallest tet volume ratio {ratio:.2f}"
    for label, kappa in (("rest fit, hard", None), ("rest fit, κ = 20", DEFAULT_KAPPA)):
        out.append({**fit.row(name, label, kappa=kappa, note=fit_note), "tet_volume_ratio_min": ratio})
    out.append(probe.oracle_row(name))
    return out, noise


# --------------------------------------------------------------------------- the study
def run_study(model=None, only=None, log=print) -> dict:
    """{"rows": [...], "recordings": {name: facts}, "skipped": note or None, "elapsed_s"}."""
    from tonguevis.sim import TongueModel
    from tonguevis.workflows import open_recording

    t_start = time.perf_counter()
    model = model or TongueModel.default()
    available = [(SHARED / rel, smap, name) for rel, smap, name in RECORDINGS if (SHARED / rel).exists()]
    if only:
        available = [a for a in available if a[2] in only or a[0].stem in only]
    if not available:
        return {"rows": [], "recordings": {}, "elapsed_s": 0.0,
                "skipped": "../shared/data was not available: no real recording studied."}
    rows, facts = [], {}
    var = variants(model)
    for path, smap, name in available:
        recording = open_recording(path, smap)
        _warm_up(recording, model)
        for label, mdl, rec, kwargs, note in full_candidates(model, var, recording):
            rows.append(full_row(name, label, mdl, rec, kwargs, note))
            log(_line(rows[-1]))
        rows.append(spring_in_dynamics_row(name, model, recording))
        log(_line(rows[-1]))
        prows, noise = probe_rows(name, model, recording)
        for r in prows:
            rows.append(r)
            log(_line(r))
        from tonguevis.preprocess.targets import prepare_targets

        prep = prepare_targets(recording, model, "speaker", None)
        facts[name] = {"file": path.name, "frames": int(recording.n_samples), "rate_hz": float(recording.rate),
                       "sensors": list(prep.names), "rest": prep.rest.as_dict(),
                       "sensor_noise_mm": 1e3 * noise, "alignment_rms_mm": 1e3 * prep.alignment_rms,
                       "has_orientations": sorted(n for n, o in recording.orientations.items()
                                                  if n in prep.names and np.any(np.abs(np.nan_to_num(o)) > 0))}
    return {"rows": rows, "recordings": facts, "skipped": None, "elapsed_s": time.perf_counter() - t_start}


def _warm_up(recording, model):
    """Compile the kernels before anything is timed."""
    from tonguevis.sim import simulate

    n = min(recording.n_samples, 50)
    short = recording.with_sensors({k: v[:n] for k, v in recording.sensors.items()}, times=recording.times[:n],
                                   orientations={k: v[:n] for k, v in recording.orientations.items()},
                                   audio=None, labels=[])
    try:
        simulate(short, model, rest=(float(short.times[0]), float(short.times[min(n, 10) - 1])))
    except Exception:  # noqa: BLE001 - a warm-up only
        pass


def _line(row):
    f = lambda v, d=2: "–" if v is None or not np.isfinite(v) else f"{v:.{d}f}"  # noqa: E731
    return (f"{row['recording']:9s} {row['candidate']:48s} {f(row['model_rmse_mm'])} (r {f(row['model_corr'])}) "
            f"kin {f(row['kinematic_rmse_mm'])} amp {f(row['amplification'])}/{f(row['amplification_frame_max'])} "
            f"vol {f(row['volume_change_max_percent'])} % misfit {f(row['sensor_misfit_rms_mm'])}/"
            f"{f(row['sensor_misfit_max_mm'])} [{f(row['row_s'], 1)} s]")


# --------------------------------------------------------------------------- tables
def fmt(v, d=2):
    return "–" if v is None or (isinstance(v, float) and not np.isfinite(v)) else f"{v:.{d}f}"


def _table(rows):
    return "\n".join("| " + " | ".join(map(str, r)) + " |" for r in [rows[0], ["---"] * len(rows[0])] + rows[1:])


def recording_names(study):
    seen = []
    for r in study["rows"]:
        if r["recording"] not in seen:
            seen.append(r["recording"])
    return seen


def summary_table(study) -> str:
    """Candidates × recordings: mean held-out RMSE mm, amplification, volume %; bold where the RMSE is at or
    below the kinematic baseline's."""
    names = recording_names(study)
    by = {(r["recording"], r["candidate"]): r for r in study["rows"]}
    candidates = []
    for r in study["rows"]:
        if r["candidate"] not in candidates:
            candidates.append(r["candidate"])
    first = {n: next(r for r in study["rows"] if r["recording"] == n) for n in names}
    out = [["candidate", "kind"] + names, ["kinematic RBF baseline", "no mesh"]
           + [f"{fmt(first[n]['kinematic_rmse_mm'])}" for n in names]]
    for cand in candidates:
        kind = next(r["kind"] for r in study["rows"] if r["candidate"] == cand)
        cells = []
        for n in names:
            r = by.get((n, cand))
            if r is None:
                cells.append("")
                continue
            rmse = fmt(r["model_rmse_mm"])
            if r["model_rmse_mm"] <= r["kinematic_rmse_mm"] + 5e-3:
                rmse = f"**{rmse}**"
            extra = ("" if r["amplification"] is None else
                     f" · ×{fmt(r['amplification'])} · {fmt(r['volume_change_max_percent'])} %")
            cells.append(rmse + extra)
        out.append([cand, kind] + cells)
    return _table(out)


def detail_tables(study) -> list[str]:
    """One table per recording: every column of every row."""
    out = []
    for n in recording_names(study):
        rows = [r for r in study["rows"] if r["recording"] == n]
        names = list(rows[0]["sensors"])
        table = [["candidate", "model RMSE (r)", "per sensor: RMSE (r)", "amplification (frame max)",
                  "volume max %", "misfit RMS / max mm", "recovered / flagged", "simulate s", "row s", "note"]]
        kin = rows[0]
        table.append(["kinematic RBF baseline", f"{fmt(kin['kinematic_rmse_mm'])} ({fmt(kin['kinematic_corr'])})",
                      " · ".join(f"{s} {fmt(kin['sensors'][s]['kinematic_rmse_mm'])} "
                                 f"({fmt(kin['sensors'][s]['kinematic_corr'])})" for s in names),
                      "", "", "", "", "", "", "no mesh: interpolation of the drivers"])
        for r in rows:
            per = " · ".join(f"{s} {fmt(r['sensors'][s]['model_rmse_mm'])} ({fmt(r['sensors'][s]['model_corr'])})"
                             for s in names if s in r["sensors"])
            flagged = ("–" if r["recovered_frames"] is None else f"{r['recovered_frames']} / {r['flagged_frames']}")
            table.append([r["candidate"], f"{fmt(r['model_rmse_mm'])} ({fmt(r['model_corr'])})", per,
                          f"{fmt(r['amplification'])} ({fmt(r['amplification_frame_max'], 1)})",
                          fmt(r["volume_change_max_percent"]),
                          f"{fmt(r['sensor_misfit_rms_mm'])} / {fmt(r['sensor_misfit_max_mm'])}", flagged,
                          fmt(r["simulate_s"], 1), fmt(r["row_s"], 1), r["note"]])
        out.append(_table(table))
    return out


def summary_block(study) -> list[str]:
    """The legend and the candidates × recordings table, as Markdown lines."""
    return [
        "Mean held-out RMSE (mm, leave-one-sensor-out, model frame) · far-field amplification · largest volume "
        "change, per recording; **bold**: at or below the kinematic baseline. Full-pipeline rows are "
        "`validate(..., quasi_static=False)` (dynamic, warped, shipped tongue, 100 modes, speaker landmarks "
        "unless said); κ is the sensor stiffness in units of the tongue's own point stiffness at the sensor "
        "nodes (targets projected onto the tongue's deformations, then held exactly); *hard* is the paper's "
        "Lagrange multipliers on the raw targets. Probe rows are a linear quasi-static solve on the frames where "
        "every sensor is valid, to be compared with the probe's own *hard* and *κ = 20* rows (the probe's volume "
        "change is that of unwarped displacements, larger than the warped model's).",
        "",
        summary_table(study),
    ]


def details_block(study) -> list[str]:
    """One table per recording with every column, and the column legend, as Markdown lines."""
    lines = []
    facts = study.get("recordings", {})
    for name, table in zip(recording_names(study), detail_tables(study)):
        f = facts.get(name, {})
        head = f"#### {name}"
        if f:
            rest = f.get("rest", {})
            interval = rest.get("interval")
            head += (f" (`{f['file']}`: {f['frames']} frames at {f['rate_hz']:.0f} Hz; sensors "
                     f"{', '.join(f['sensors'])}; measured sensor noise {f['sensor_noise_mm']:.3f} mm"
                     + (f"; rest {interval[0]:.2f}-{interval[1]:.2f} s ({rest.get('how', '')})" if interval else "")
                     + ")")
        lines += [head, "", table, ""]
    lines += ["Columns: model RMSE (r) = mean over held-out sensors; amplification = largest node displacement / "
              "largest sensor displacement over the run with every sensor driving (in parentheses the largest "
              "per-frame ratio, frames where a sensor moved ≥ 1 mm); misfit = distance of the sensor nodes from "
              "the measured sensors; recovered = frames that ran away and kept the previous shape, flagged = "
              "frames no tongue could produce (volume > 25 % or a node 10× the furthest sensor); simulate s = one "
              "`simulate()` of the whole recording (full pipeline) or the integration (spring row); row s = the "
              f"whole row. Study time {study['elapsed_s'] / 60:.1f} min."]
    return lines


def render(study) -> str:
    """The study as Markdown (no heading of its own: validate_all.py places it)."""
    if study.get("skipped"):
        return study["skipped"] + "\n"
    return "\n".join(summary_block(study) + [""] + details_block(study)) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json-dir", type=Path, help="write fidelity.json (summary scores) here, outside the repository")
    parser.add_argument("--out", type=Path, help="write the Markdown tables here (default: standard output)")
    parser.add_argument("--only", nargs="*", help="recording short names or file stems (default: all)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s: %(message)s")
    study = run_study(only=args.only, log=lambda s: print(s, file=sys.stderr, flush=True))
    if study.get("skipped"):
        print(study["skipped"], file=sys.stderr)
    if args.json_dir is not None:
        args.json_dir.mkdir(parents=True, exist_ok=True)
        (args.json_dir / "fidelity.json").write_text(json.dumps(study, indent=1, default=_json_default))
    text = render(study)
    if args.out is None:
        sys.stdout.write(text)
    else:
        from tonguevis._files import atomic_write_text

        atomic_write_text(args.out, text)
        print(f"wrote {args.out}", file=sys.stderr)
    return 0


def _json_default(obj):
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(type(obj))


if __name__ == "__main__":
    sys.exit(main())
