"""The constrained Newmark integrator compiled with warp-lang (``backend="warp"``, the fast path).

The same algorithm as :mod:`tonguevis.sim.newmark` and :mod:`tonguevis.sim.constrained`
(the readable reference; a test proves both equal): per frame, Newton on
A q̈ = b + Φ_sᵀR̃_sᵀμ, R̃(W_s q)Φ_s q + Cμ = c, started at the previous frame's q,
with the Woodbury form of the Newton matrix, the capped sensor-rotation step,
the backtracking line search and the recovery of a frame that runs away
(previous shape kept, velocity reset).  One warp thread integrates one whole trial
(frames are sequential); several trials run as one launch.  The Python
reference spends its time in NumPy call overhead on 12 × 100 arrays; compiled,
a frame costs tens of microseconds.
"""



import threading

import numpy as np

from tonguevis.sim.newmark import IntegrationResult, NewmarkSettings

_lock = threading.Lock()
_kernel = None
_wp = None

# Scratch vectors of length m per trial.
_V_Q, _V_QD, _V_QDD, _V_QP, _V_QDP, _V_B, _V_TRIAL, _V_RSTAT, _V_TMP, _V_DQDD, _V_AUX, _V_QPREV = range(12)
N_VECTORS = 12
# Scratch vectors of length 3S per trial.
_W_C, _W_MULT, _W_DMULT, _W_RCON, _W_RCON2, _W_MULT2, _W_RHOW, _W_RHOP, _W_Y, _W_T1, _W_T2, _W_COMP = range(12)
N_SMALLVEC = 12
# Scratch 3S × (3S + 1) matrices per trial.
_S_H, _S_E, _S_SOL, _S_M = range(4)
N_SMALL = 4


def _build():  # noqa: C901 - one kernel and its helpers, kept together
    global _kernel, _wp
    with _lock:
        if _kernel is not None:
            return
        from tonguevis._backend import load_warp

        wp = load_warp()
        f64 = wp.float64

        @wp.func
        def coeffs(t: f64):
            t2 = t * t
            a = f64(0.0)
            b = f64(0.0)
            da = f64(0.0)
            db = f64(0.0)
            if t < f64(0.05):
                a = f64(0.5) - t2 / f64(24.0) + t2 * t2 / f64(720.0)
                b = f64(1.0) / f64(6.0) - t2 / f64(120.0) + t2 * t2 / f64(5040.0)
                da = f64(-1.0) / f64(12.0) + t2 / f64(180.0) - t2 * t2 / f64(6720.0)
                db = f64(-1.0) / f64(60.0) + t2 / f64(1260.0) - t2 * t2 / f64(60480.0)
            else:
                s = wp.sin(t)
                c = wp.cos(t)
                a = (f64(1.0) - c) / t2
                b = (t - s) / (t2 * t)
                da = (t * s - f64(2.0) * (f64(1.0) - c)) / (t2 * t2)
                db = ((f64(1.0) - c) * t - f64(3.0) * (t - s)) / (t2 * t2 * t)
            return a, b, da, db

        @wp.func
        def eye3():
            return wp.mat33d(f64(1.0), f64(0.0), f64(0.0), f64(0.0), f64(1.0), f64(0.0), f64(0.0), f64(0.0), f64(1.0))

        @wp.func
        def rot_and_jac(w: wp.vec3d, d: wp.vec3d):
            """g = R̃(w) d, R̃(w) and ∂g/∂w (see rotation.rotate_accumulated_jacobian)."""
            a, b, da, db = coeffs(wp.length(w))
            wd = wp.cross(w, d)
            wwd = wp.cross(w, wd)
            g = d + a * wd + b * wwd
            sk = wp.skew(w)
            rot = eye3() + a * sk + b * (sk * sk)
            dg = da * wp.outer(wd, w) - a * wp.skew(d) + db * wp.outer(wwd, w)
            dg = dg + b * (wp.dot(w, d) * eye3() + wp.outer(w, d) - f64(2.0) * wp.outer(d, w))
            return g, rot, dg

        @wp.func
        def solve_small(t: int, mat: wp.array4d(dtype=f64), mi: int, n: int, ri: int, ncols: int):
            """Gaussian elimination with partial pivoting on mat[t, mi, :n, :n]; the right-hand
            sides mat[t, ri, :n, :ncols] are overwritten by the solution."""
            for col in range(n):
                piv = col
                best = wp.abs(mat[t, mi, col, col])
                for r in range(col + 1, n):
                    v = wp.abs(mat[t, mi, r, col])
                    if v > best:
                        best = v
                        piv = r
                if piv != col:
                    for c in range(n):
                        tmp = mat[t, mi, col, c]
                        mat[t, mi, col, c] = mat[t, mi, piv, c]
                        mat[t, mi, piv, c] = tmp
                    for c in range(ncols):
                        tmp2 = mat[t, ri, col, c]
                        mat[t, ri, col, c] = mat[t, ri, piv, c]
                        mat[t, ri, piv, c] = tmp2
                p = mat[t, mi, col, col]
                if wp.abs(p) < f64(1e-300):
                    p = f64(1e-300)
                for r in range(col + 1, n):
                    fct = mat[t, mi, r, col] / p
                    if fct != f64(0.0):
                        for c in range(col, n):
                            mat[t, mi, r, c] = mat[t, mi, r, c] - fct * mat[t, mi, col, c]
                        for c in range(ncols):
                            mat[t, ri, r, c] = mat[t, ri, r, c] - fct * mat[t, ri, col, c]
            for cc in range(n):
                col = n - 1 - cc
                p = mat[t, mi, col, col]
                if wp.abs(p) < f64(1e-300):
                    p = f64(1e-300)
                for c in range(ncols):
                    acc = mat[t, ri, col, c]
                    for k in range(col + 1, n):
                        acc = acc - mat[t, mi, col, k] * mat[t, ri, k, c]
                    mat[t, ri, col, c] = acc / p

        @wp.func
        def sensor_rows(t: int, a: int, act: wp.array2d(dtype=int), mat: wp.array2d(dtype=f64),
                        v: wp.array3d(dtype=f64), vi: int, scale_by: wp.array(dtype=f64), use_scale: int):
            """(mat v)_s for sensor act[a], optionally v scaled elementwise by ``scale_by``."""
            s = act[t, a]
            out = wp.vec3d()
            for j in range(mat.shape[1]):
                x = v[t, vi, j]
                if use_scale != 0:
                    x = x * scale_by[j]
                out = out + wp.vec3d(mat[3 * s, j], mat[3 * s + 1, j], mat[3 * s + 2, j]) * x
            return out

        @wp.func
        def evaluate(t: int, qdd_i: int, mult_i: int, rcon_i: int, slot: int, n_act: int, warping: int, bn: f64,
                     act: wp.array2d(dtype=int), phi: wp.array2d(dtype=f64), ws: wp.array2d(dtype=f64),
                     a_inv: wp.array(dtype=f64), vecs: wp.array3d(dtype=f64), svec: wp.array3d(dtype=f64),
                     rotb: wp.array3d(dtype=wp.mat33d), dgb: wp.array3d(dtype=wp.mat33d),
                     wb: wp.array3d(dtype=wp.vec3d)):
            """Residuals at q = q* + β q̈ (r_stat into _V_RSTAT); R̃, ∂g/∂w, w into ``slot``; returns the merit."""
            m = phi.shape[1]
            for j in range(m):
                vecs[t, _V_AUX, j] = vecs[t, _V_QP, j] + bn * vecs[t, qdd_i, j]
            for j in range(m):
                vecs[t, _V_RSTAT, j] = vecs[t, qdd_i, j] / a_inv[j] - vecs[t, _V_B, j]
            con = f64(0.0)
            for a in range(n_act):
                d = sensor_rows(t, a, act, phi, vecs, _V_AUX, a_inv, 0)
                w = sensor_rows(t, a, act, ws, vecs, _V_AUX, a_inv, 0)
                g = d
                rot = eye3()
                dg = wp.mat33d()
                if warping != 0:
                    g, rot, dg = rot_and_jac(w, d)
                rotb[t, slot, a] = rot
                dgb[t, slot, a] = dg
                wb[t, slot, a] = w
                mu = wp.vec3d(svec[t, mult_i, 3 * a], svec[t, mult_i, 3 * a + 1], svec[t, mult_i, 3 * a + 2])
                rt_mu = wp.transpose(rot) * mu
                s = act[t, a]
                for j in range(m):
                    vecs[t, _V_RSTAT, j] = vecs[t, _V_RSTAT, j] - (
                        phi[3 * s, j] * rt_mu[0] + phi[3 * s + 1, j] * rt_mu[1] + phi[3 * s + 2, j] * rt_mu[2])
                for r in range(3):
                    rc = svec[t, _W_C, 3 * a + r] - g[r] - svec[t, _W_COMP, 3 * a + r] * mu[r]
                    svec[t, rcon_i, 3 * a + r] = rc
                    con = con + rc * rc
            stat = f64(0.0)
            for j in range(m):
                stat = stat + bn * bn * vecs[t, _V_RSTAT, j] * vecs[t, _V_RSTAT, j]
            return wp.sqrt(stat + con)

        @wp.func
        def fill_h(t: int, n_act: int, act: wp.array2d(dtype=int), qm: wp.array2d(dtype=f64),
                   pm: wp.array2d(dtype=f64), rotb: wp.array3d(dtype=wp.mat33d), dgb: wp.array3d(dtype=wp.mat33d),
                   small: wp.array4d(dtype=f64)):
            """H = R̃ Q + D P over the active sensors (J A⁻¹ Φ_sᵀ)."""
            for a in range(n_act):
                rot = rotb[t, 0, a]
                dg = dgb[t, 0, a]
                s = act[t, a]
                for b2 in range(n_act):
                    s2 = act[t, b2]
                    for c in range(3):
                        qv = wp.vec3d(qm[3 * s, 3 * s2 + c], qm[3 * s + 1, 3 * s2 + c], qm[3 * s + 2, 3 * s2 + c])
                        pv = wp.vec3d(pm[3 * s, 3 * s2 + c], pm[3 * s + 1, 3 * s2 + c], pm[3 * s + 2, 3 * s2 + c])
                        hv = rot * qv + dg * pv
                        for r in range(3):
                            small[t, _S_H, 3 * a + r, 3 * b2 + c] = hv[r]

        @wp.func
        def linear_start(t: int, n_act: int, warping: int, bn: f64, act: wp.array2d(dtype=int),
                         phi: wp.array2d(dtype=f64), ws: wp.array2d(dtype=f64), qm: wp.array2d(dtype=f64),
                         pm: wp.array2d(dtype=f64), a_inv: wp.array(dtype=f64), vecs: wp.array3d(dtype=f64),
                         svec: wp.array3d(dtype=f64), small: wp.array4d(dtype=f64),
                         rotb: wp.array3d(dtype=wp.mat33d), dgb: wp.array3d(dtype=wp.mat33d),
                         wb: wp.array3d(dtype=wp.vec3d)):
            """_V_TRIAL = q̈ of the problem linearised at the previous frame's q, _W_MULT its forces;
            with ``warping`` 0 the exact solution of the linear (unwarped) constraint."""
            m = phi.shape[1]
            n_c = 3 * n_act
            # Start at the previous frame's q with the forces of the linearised problem there.
            for j in range(m):
                vecs[t, _V_TRIAL, j] = (vecs[t, _V_Q, j] - vecs[t, _V_QP, j]) / bn
                vecs[t, _V_TMP, j] = vecs[t, _V_TRIAL, j] - a_inv[j] * vecs[t, _V_B, j]
            for k in range(n_c):
                svec[t, _W_MULT, k] = f64(0.0)
            evaluate(t, _V_TRIAL, _W_MULT, _W_RCON, 0, n_act, warping, bn, act, phi, ws, a_inv, vecs, svec,
                     rotb, dgb, wb)
            fill_h(t, n_act, act, qm, pm, rotb, dgb, small)
            for a in range(n_act):
                rot = rotb[t, 0, a]
                dg = dgb[t, 0, a]
                jv = rot * sensor_rows(t, a, act, phi, vecs, _V_TMP, a_inv, 0) + dg * sensor_rows(
                    t, a, act, ws, vecs, _V_TMP, a_inv, 0)
                for r in range(3):
                    small[t, _S_SOL, 3 * a + r, 0] = svec[t, _W_RCON, 3 * a + r] + bn * jv[r]
            # M = β H R̃ᵀ + C
            for k in range(n_c):
                for a in range(n_act):
                    rot = rotb[t, 0, a]
                    for c in range(3):
                        acc = f64(0.0)
                        for r in range(3):
                            acc = acc + small[t, _S_H, k, 3 * a + r] * rot[c, r]
                        small[t, _S_M, k, 3 * a + c] = bn * acc
                small[t, _S_M, k, k] = small[t, _S_M, k, k] + svec[t, _W_COMP, k]
            solve_small(t, small, _S_M, n_c, _S_SOL, 1)
            for k in range(n_c):
                svec[t, _W_MULT, k] = small[t, _S_SOL, k, 0]
            for j in range(m):
                vecs[t, _V_TRIAL, j] = vecs[t, _V_B, j]
            for a in range(n_act):
                mu = wp.vec3d(svec[t, _W_MULT, 3 * a], svec[t, _W_MULT, 3 * a + 1], svec[t, _W_MULT, 3 * a + 2])
                rt_mu = wp.transpose(rotb[t, 0, a]) * mu
                s = act[t, a]
                for j in range(m):
                    vecs[t, _V_TRIAL, j] = vecs[t, _V_TRIAL, j] + (
                        phi[3 * s, j] * rt_mu[0] + phi[3 * s + 1, j] * rt_mu[1] + phi[3 * s + 2, j] * rt_mu[2])
            for j in range(m):
                vecs[t, _V_TRIAL, j] = a_inv[j] * vecs[t, _V_TRIAL, j]

        @wp.kernel
        def newmark(lam: wp.array(dtype=f64), a_inv: wp.array(dtype=f64), damp: wp.array(dtype=f64),
                    phi: wp.array2d(dtype=f64), ws: wp.array2d(dtype=f64), qm: wp.array2d(dtype=f64),
                    pm: wp.array2d(dtype=f64), targets: wp.array3d(dtype=f64), comp: wp.array3d(dtype=f64),
                    ext: wp.array3d(dtype=f64),
                    h: f64, bn: f64, tol: f64, stat_rtol: f64, max_iter: int, max_rot: f64, runaway: f64,
                    warping: int,
                    out_q: wp.array3d(dtype=f64), out_qd: wp.array3d(dtype=f64), out_qdd: wp.array3d(dtype=f64),
                    out_res: wp.array3d(dtype=f64), out_conv: wp.array2d(dtype=int), out_iter: wp.array2d(dtype=int),
                    out_rec: wp.array2d(dtype=int),
                    vecs: wp.array3d(dtype=f64), svec: wp.array3d(dtype=f64), small: wp.array4d(dtype=f64),
                    rotb: wp.array3d(dtype=wp.mat33d), dgb: wp.array3d(dtype=wp.mat33d),
                    wb: wp.array3d(dtype=wp.vec3d), act: wp.array2d(dtype=int), wasact: wp.array2d(dtype=int),
                    offset: int):
            # offset: the recording's frame number of targets[:, 0]; past 0 the state (q, q̇, q̈ and
            # the scratch arrays) is the previous segment's, so segments integrate as one run.
            t = wp.tid()
            m = lam.shape[0]
            n_frames = targets.shape[1]
            n_sensors = targets.shape[2] // 3
            if offset == 0:
                for j in range(m):
                    vecs[t, _V_Q, j] = f64(0.0)
                    vecs[t, _V_QD, j] = f64(0.0)
                    vecs[t, _V_QDD, j] = f64(0.0)
            for i in range(n_frames):
                # A sensor that acted in the last frame and does not now: velocity from the last two
                # shapes, acceleration zero (see newmark.py); then this frame's active flags.
                released = int(0)
                for s in range(n_sensors):
                    now = int(1)
                    for r in range(3):
                        if wp.isnan(targets[t, i, 3 * s + r]):
                            now = int(0)
                    if not wp.isfinite(comp[t, i, s]):
                        now = int(0)
                    if i + offset > 0 and wasact[t, s] == 1 and now == 0:
                        released = int(1)
                    wasact[t, s] = now
                for j in range(m):
                    if released == 1:
                        vecs[t, _V_QD, j] = (vecs[t, _V_Q, j] - vecs[t, _V_QPREV, j]) / h
                        vecs[t, _V_QDD, j] = f64(0.0)
                    vecs[t, _V_QPREV, j] = vecs[t, _V_Q, j]
                for j in range(m):
                    qp = vecs[t, _V_Q, j] + h * vecs[t, _V_QD, j] + bn * vecs[t, _V_QDD, j]
                    qdp = vecs[t, _V_QD, j] + f64(0.5) * h * vecs[t, _V_QDD, j]
                    vecs[t, _V_QP, j] = qp
                    vecs[t, _V_QDP, j] = qdp
                    vecs[t, _V_B, j] = -damp[j] * qdp - lam[j] * qp + ext[t, wp.min(i, ext.shape[1] - 1), j]
                n_act = int(0)
                for s in range(n_sensors):
                    ok = int(1)
                    for r in range(3):
                        if wp.isnan(targets[t, i, 3 * s + r]):
                            ok = int(0)
                    if not wp.isfinite(comp[t, i, s]):
                        ok = int(0)
                    if ok == 1:
                        act[t, n_act] = s
                        for r in range(3):
                            svec[t, _W_C, 3 * n_act + r] = targets[t, i, 3 * s + r]
                            svec[t, _W_COMP, 3 * n_act + r] = comp[t, i, s]
                        n_act = n_act + 1
                n_c = 3 * n_act
                conv = int(1)
                iters = int(0)
                if n_act == 0:
                    for j in range(m):
                        vecs[t, _V_TRIAL, j] = a_inv[j] * vecs[t, _V_B, j]
                else:
                    linear_start(t, n_act, warping, bn, act, phi, ws, qm, pm, a_inv, vecs, svec, small, rotb, dgb,
                                 wb)
                    iters = int(1)
                    if warping != 0:
                        merit = evaluate(t, _V_TRIAL, _W_MULT, _W_RCON, 0, n_act, warping, bn, act, phi, ws, a_inv,
                                         vecs, svec, rotb, dgb, wb)
                        stat_scale = f64(0.0)
                        for j in range(m):
                            stat_scale = wp.max(stat_scale, wp.abs(vecs[t, _V_TRIAL, j] / a_inv[j]))
                            stat_scale = wp.max(stat_scale, wp.abs(vecs[t, _V_B, j]))
                        tol_stat = tol + stat_rtol * bn * stat_scale
                        conv = int(0)
                        done = int(0)
                        it = int(1)
                        while done == 0:
                            worst = f64(0.0)
                            for k in range(n_c):
                                worst = wp.max(worst, wp.abs(svec[t, _W_RCON, k]))
                            worst_stat = f64(0.0)
                            for j in range(m):
                                worst_stat = wp.max(worst_stat, wp.abs(bn * vecs[t, _V_RSTAT, j]))
                            if worst < tol and worst_stat < tol_stat:
                                conv = int(1)
                                done = int(1)
                            elif it > max_iter:
                                done = int(1)
                            else:
                                # ρ_w = W_s A⁻¹ r_stat, ρ_φ = Φ_s A⁻¹ r_stat
                                for a in range(n_act):
                                    rw = sensor_rows(t, a, act, ws, vecs, _V_RSTAT, a_inv, 1)
                                    rp = sensor_rows(t, a, act, phi, vecs, _V_RSTAT, a_inv, 1)
                                    for r in range(3):
                                        svec[t, _W_RHOW, 3 * a + r] = rw[r]
                                        svec[t, _W_RHOP, 3 * a + r] = rp[r]
                                # E = I - β X P and right-hand sides [R̃ᵀ, β X ρ_w]; X = -∂g/∂w at (-w, μ).
                                for a in range(n_act):
                                    mu = wp.vec3d(svec[t, _W_MULT, 3 * a], svec[t, _W_MULT, 3 * a + 1],
                                                  svec[t, _W_MULT, 3 * a + 2])
                                    g2, rot2, dgt = rot_and_jac(-wb[t, 0, a], mu)
                                    xb = -dgt
                                    rot = rotb[t, 0, a]
                                    s = act[t, a]
                                    rwv = wp.vec3d(svec[t, _W_RHOW, 3 * a], svec[t, _W_RHOW, 3 * a + 1],
                                                   svec[t, _W_RHOW, 3 * a + 2])
                                    xr = xb * rwv
                                    for r in range(3):
                                        for b2 in range(n_act):
                                            s2 = act[t, b2]
                                            for c in range(3):
                                                acc = f64(0.0)
                                                for k in range(3):
                                                    acc = acc + xb[r, k] * pm[3 * s + k, 3 * s2 + c]
                                                e = -bn * acc
                                                if a == b2 and r == c:
                                                    e = e + f64(1.0)
                                                small[t, _S_E, 3 * a + r, 3 * b2 + c] = e
                                                rt = f64(0.0)
                                                if a == b2:
                                                    rt = rot[c, r]
                                                small[t, _S_SOL, 3 * a + r, 3 * b2 + c] = rt
                                        small[t, _S_SOL, 3 * a + r, n_c] = bn * xr[r]
                                solve_small(t, small, _S_E, n_c, _S_SOL, n_c + 1)
                                fill_h(t, n_act, act, qm, pm, rotb, dgb, small)
                                # β H E⁻¹R̃ᵀ Δμ = r_con + β(R̃ ρ_φ + D ρ_w) + β H E⁻¹ β X ρ_w
                                for a in range(n_act):
                                    rot = rotb[t, 0, a]
                                    dg = dgb[t, 0, a]
                                    rp = wp.vec3d(svec[t, _W_RHOP, 3 * a], svec[t, _W_RHOP, 3 * a + 1],
                                                  svec[t, _W_RHOP, 3 * a + 2])
                                    rw = wp.vec3d(svec[t, _W_RHOW, 3 * a], svec[t, _W_RHOW, 3 * a + 1],
                                                  svec[t, _W_RHOW, 3 * a + 2])
                                    base = rot * rp + dg * rw
                                    for r in range(3):
                                        svec[t, _W_T1, 3 * a + r] = svec[t, _W_RCON, 3 * a + r] + bn * base[r]
                                for k in range(n_c):
                                    acc = svec[t, _W_T1, k]
                                    for l in range(n_c):
                                        acc = acc + bn * small[t, _S_H, k, l] * small[t, _S_SOL, l, n_c]
                                    small[t, _S_E, k, n_c] = acc
                                    for l in range(n_c):
                                        sacc = f64(0.0)
                                        for p in range(n_c):
                                            sacc = sacc + small[t, _S_H, k, p] * small[t, _S_SOL, p, l]
                                        small[t, _S_M, k, l] = bn * sacc
                                    small[t, _S_M, k, k] = small[t, _S_M, k, k] + svec[t, _W_COMP, k]
                                for k in range(n_c):
                                    svec[t, _W_T2, k] = small[t, _S_E, k, n_c]
                                for k in range(n_c):
                                    small[t, _S_H, k, 0] = svec[t, _W_T2, k]
                                solve_small(t, small, _S_M, n_c, _S_H, 1)
                                for k in range(n_c):
                                    svec[t, _W_DMULT, k] = small[t, _S_H, k, 0]
                                # y = E⁻¹R̃ᵀ Δμ - E⁻¹ β X ρ_w ; Δq̈ = A⁻¹(Φ_sᵀ y - r_stat)
                                for k in range(n_c):
                                    acc = -small[t, _S_SOL, k, n_c]
                                    for l in range(n_c):
                                        acc = acc + small[t, _S_SOL, k, l] * svec[t, _W_DMULT, l]
                                    svec[t, _W_Y, k] = acc
                                for j in range(m):
                                    vecs[t, _V_DQDD, j] = -vecs[t, _V_RSTAT, j]
                                for a in range(n_act):
                                    s = act[t, a]
                                    for j in range(m):
                                        vecs[t, _V_DQDD, j] = vecs[t, _V_DQDD, j] + (
                                            phi[3 * s, j] * svec[t, _W_Y, 3 * a]
                                            + phi[3 * s + 1, j] * svec[t, _W_Y, 3 * a + 1]
                                            + phi[3 * s + 2, j] * svec[t, _W_Y, 3 * a + 2])
                                for j in range(m):
                                    vecs[t, _V_DQDD, j] = a_inv[j] * vecs[t, _V_DQDD, j]
                                # |W_s β Δq̈| = |β (P y - ρ_w)|: cap the sensor-rotation change.
                                dw = f64(0.0)
                                for a in range(n_act):
                                    s = act[t, a]
                                    for r in range(3):
                                        acc = -svec[t, _W_RHOW, 3 * a + r]
                                        for b2 in range(n_act):
                                            s2 = act[t, b2]
                                            for c in range(3):
                                                acc = acc + pm[3 * s + r, 3 * s2 + c] * svec[t, _W_Y, 3 * b2 + c]
                                        dw = wp.max(dw, wp.abs(bn * acc))
                                step = f64(1.0)
                                if dw > max_rot:
                                    step = f64(max_rot / dw)
                                trial_merit = merit
                                searching = int(1)
                                while searching == 1:
                                    for j in range(m):
                                        vecs[t, _V_TMP, j] = vecs[t, _V_TRIAL, j] + step * vecs[t, _V_DQDD, j]
                                    for k in range(n_c):
                                        svec[t, _W_MULT2, k] = svec[t, _W_MULT, k] + step * svec[t, _W_DMULT, k]
                                    trial_merit = evaluate(t, _V_TMP, _W_MULT2, _W_RCON2, 1, n_act, warping, bn, act,
                                                           phi, ws, a_inv, vecs, svec, rotb, dgb, wb)
                                    if trial_merit < merit or step < f64(1e-4):
                                        searching = int(0)
                                    else:
                                        step = step * f64(0.5)
                                if not (trial_merit < merit):
                                    done = int(1)  # no descent (or NaN): keep the last iterate, flagged
                                else:
                                    merit = trial_merit
                                    for j in range(m):
                                        vecs[t, _V_TRIAL, j] = vecs[t, _V_TMP, j]
                                    for k in range(n_c):
                                        svec[t, _W_MULT, k] = svec[t, _W_MULT2, k]
                                        svec[t, _W_RCON, k] = svec[t, _W_RCON2, k]
                                    for a in range(n_act):
                                        rotb[t, 0, a] = rotb[t, 1, a]
                                        dgb[t, 0, a] = dgb[t, 1, a]
                                        wb[t, 0, a] = wb[t, 1, a]
                                    it = it + 1
                        iters = wp.min(it, max_iter)
                    # A non-finite or runaway frame keeps the previous frame's shape; velocity reset.
                    recover = int(0)
                    for j in range(m):
                        qn = vecs[t, _V_QP, j] + bn * vecs[t, _V_TRIAL, j]
                        vecs[t, _V_AUX, j] = qn
                        if not wp.isfinite(qn):
                            recover = int(1)
                    if warping != 0 and recover == 0:
                        for s in range(n_sensors):
                            wv = wp.vec3d()
                            for j in range(m):
                                x = vecs[t, _V_AUX, j]
                                wv = wv + wp.vec3d(ws[3 * s, j], ws[3 * s + 1, j], ws[3 * s + 2, j]) * x
                            if wp.length(wv) > runaway:
                                recover = int(1)
                    if recover != 0:
                        for j in range(m):
                            vecs[t, _V_TRIAL, j] = (vecs[t, _V_Q, j] - vecs[t, _V_QP, j]) / bn
                    out_rec[t, i] = recover
                # Commit the frame.
                for j in range(m):
                    qdd = vecs[t, _V_TRIAL, j]
                    q = vecs[t, _V_QP, j] + bn * qdd
                    vecs[t, _V_Q, j] = q
                    vecs[t, _V_QD, j] = vecs[t, _V_QDP, j] + f64(0.5) * h * qdd
                    vecs[t, _V_QDD, j] = qdd
                    if out_rec[t, i] != 0:
                        vecs[t, _V_QD, j] = f64(0.0)
                        vecs[t, _V_QDD, j] = f64(0.0)
                    out_q[t, i, j] = q
                    k = wp.min(i, out_qd.shape[1] - 1)  # a one-frame buffer when the rates are not kept
                    out_qd[t, k, j] = vecs[t, _V_QD, j]
                    out_qdd[t, k, j] = vecs[t, _V_QDD, j]
                out_conv[t, i] = conv
                out_iter[t, i] = iters
                for s in range(n_sensors):
                    act[t, 0] = s
                    d = sensor_rows(t, 0, act, phi, vecs, _V_Q, a_inv, 0)
                    w = sensor_rows(t, 0, act, ws, vecs, _V_Q, a_inv, 0)
                    g = d
                    if warping != 0:
                        g, rot3, dg3 = rot_and_jac(w, d)
                    tv = wp.vec3d(targets[t, i, 3 * s], targets[t, i, 3 * s + 1], targets[t, i, 3 * s + 2])
                    out_res[t, i, s] = wp.length(g - tv)

        _wp = wp
        _kernel = newmark


def integrate_compiled(
    eigenvalues: np.ndarray,
    phi_s: np.ndarray,
    w_s: np.ndarray,
    targets: np.ndarray,
    settings: NewmarkSettings,
    compliance: np.ndarray | float = 0.0,
    external: np.ndarray | None = None,
    device: str = "cpu",
    rates: bool = True,
) -> IntegrationResult | list[IntegrationResult]:
    """Compiled :func:`tonguevis.sim.newmark.integrate`.

    targets : (F, S, 3) for one trial, or (T, F, S, 3) for T trials integrated
    in one launch (then a list of results is returned).
    compliance : m/N, broadcast to (F, S) or (T, F, S); 0 = hard, inf = not acting.
    external : external modal forces, (F, m) or (T, F, m), or None.
    rates : keep q̇ and q̈ of every frame (else ``qd`` and ``qdd`` are None: a long recording
        then holds q alone, 144 MB for 30 minutes at 100 Hz instead of three times that).
    The whole run as one segment of a :class:`CompiledIntegrator`.
    """
    batch = targets.ndim == 4
    tg = targets if batch else targets[None]
    integrator = CompiledIntegrator(eigenvalues, phi_s, w_s, settings, n_sensors=tg.shape[2], trials=tg.shape[0],
                                    device=device, rates=rates)
    results = integrator.advance(tg, compliance, external)  # (F, S) and (F, m) broadcast over the one trial
    return results if batch else results[0]


class CompiledIntegrator:
    """The compiled frame loop, resumable: :meth:`advance` integrates the next frames from where the
    last call stopped (q, q̇, q̈ and every scratch array kept between launches), so a recording
    integrated in segments gives bit for bit the q of one launch (a test checks it).  This is what lets
    the figures of the frames done be computed while the next are integrated, and the app show the
    first seconds of a long recording before the rest is simulated.

    trials : T trials integrated side by side (one warp thread each); n_sensors : S.
    """

    def __init__(self, eigenvalues: np.ndarray, phi_s: np.ndarray, w_s: np.ndarray, settings: NewmarkSettings,
                 n_sensors: int, trials: int = 1, device: str = "cpu", rates: bool = True):
        _build()
        wp = _wp
        self.device, self.rates, self.settings = device, rates, settings
        self.trials, self.n_sensors = int(trials), int(n_sensors)
        self.frames_done = 0
        lam = np.ascontiguousarray(eigenvalues, dtype=np.float64)
        m = self.m = len(lam)
        n_c = 3 * n_sensors
        h = float(settings.dt)
        bn = h * h / 4.0
        damp = settings.alpha + settings.beta * lam
        a_inv = 1.0 / (1.0 + 0.5 * h * damp + bn * lam)
        phi2 = phi_s.reshape(n_c, m)
        q_full = (phi2 * a_inv) @ phi2.T  # Φ_s A⁻¹ Φ_sᵀ
        p_full = (w_s.reshape(n_c, m) * a_inv) @ phi2.T  # W_s A⁻¹ Φ_sᵀ
        self._constants = [self._array(x) for x in (lam, a_inv, damp, phi2, w_s.reshape(n_c, m), q_full, p_full)]
        self._scalars = [h, bn]
        t = self.trials
        self._state = [  # the integrator's memory between frames, kept between segments
            wp.zeros((t, N_VECTORS, m), dtype=wp.float64, device=device),
            wp.zeros((t, N_SMALLVEC, n_c), dtype=wp.float64, device=device),
            wp.zeros((t, N_SMALL, n_c, n_c + 1), dtype=wp.float64, device=device),
            wp.zeros((t, 2, n_sensors), dtype=wp.mat33d, device=device),
            wp.zeros((t, 2, n_sensors), dtype=wp.mat33d, device=device),
            wp.zeros((t, 2, n_sensors), dtype=wp.vec3d, device=device),
            wp.zeros((t, n_sensors), dtype=wp.int32, device=device),
            wp.zeros((t, n_sensors), dtype=wp.int32, device=device),
        ]

    def _array(self, x, dtype=None):
        return _wp.array(np.ascontiguousarray(x), dtype=dtype or _wp.float64, device=self.device)

    def advance(self, targets: np.ndarray, compliance: np.ndarray | float = 0.0,
                external: np.ndarray | None = None) -> list[IntegrationResult]:
        """Integrate the next f frames of every trial; one :class:`IntegrationResult` per trial (f frames).

        targets : (T, f, S, 3) m; compliance : broadcast to (T, f, S), m/N; external : (T, f, m) or None.
        """
        from tonguevis.sim.constrained import MAX_ROTATION_STEP, RUNAWAY_ROTATION, STATIONARITY_RTOL

        wp, device, settings, m = _wp, self.device, self.settings, self.m
        tg = np.asarray(targets, dtype=np.float64)
        n_trials, n_frames, n_sensors, _ = tg.shape
        if n_trials != self.trials or n_sensors != self.n_sensors:
            raise ValueError(f"targets {tg.shape} do not fit this integrator ({self.trials} trials, "
                             f"{self.n_sensors} sensors)")
        comp = np.broadcast_to(np.asarray(compliance, dtype=np.float64), tg.shape[:3])
        ext = (np.zeros((n_trials, 1, m)) if external is None  # no forces: one frame of zeros
               else np.broadcast_to(np.asarray(external, dtype=np.float64), (n_trials, n_frames, m)))
        out_q = wp.zeros((n_trials, n_frames, m), dtype=wp.float64, device=device)
        out_qd = wp.zeros_like(out_q) if self.rates else wp.zeros((n_trials, 1, m), dtype=wp.float64, device=device)
        out_qdd = wp.zeros_like(out_qd)
        out_res = wp.zeros((n_trials, n_frames, n_sensors), dtype=wp.float64, device=device)
        out_conv = wp.zeros((n_trials, n_frames), dtype=wp.int32, device=device)
        out_iter = wp.zeros((n_trials, n_frames), dtype=wp.int32, device=device)
        out_rec = wp.zeros((n_trials, n_frames), dtype=wp.int32, device=device)
        wp.launch(
            _kernel,
            dim=n_trials,
            inputs=[
                *self._constants,
                self._array(tg.reshape(n_trials, n_frames, 3 * n_sensors)), self._array(comp), self._array(ext),
                *self._scalars, float(settings.tolerance), float(STATIONARITY_RTOL), int(settings.max_iterations),
                float(MAX_ROTATION_STEP), float(RUNAWAY_ROTATION),
                int(bool(settings.warping)),
                out_q, out_qd, out_qdd, out_res, out_conv, out_iter, out_rec, *self._state, int(self.frames_done),
            ],
            device=device,
        )
        self.frames_done += n_frames
        res = out_res.numpy()
        res[np.any(np.isnan(tg), axis=3)] = np.nan
        rates = self.rates
        return [
            IntegrationResult(q, qd if rates else None, qdd if rates else None, r, c.astype(bool),
                              it.astype(np.int64), rec.astype(bool))
            for q, qd, qdd, r, c, it, rec in zip(
                out_q.numpy(), out_qd.numpy(), out_qdd.numpy(), res, out_conv.numpy(), out_iter.numpy(),
                out_rec.numpy()
            )
        ]
