"""The domains' exact reduced StVK force, energy and tangent compiled with warp-lang (issue 26 item 5).

The same sums as :meth:`tonguevis.sim.domains.DomainModel.full_force` and
:meth:`~tonguevis.sim.domains.DomainModel.full_tangent` (the NumPy references; a test proves them
equal to round-off), over every tet of the mesh, no cubature: u = B z by one BLAS product
(3n × r), one warp thread per tet for F, the Green strain, the stresses, the tet's energy
and its four nodal forces (accumulated at the nodes), then Bᵀ f by BLAS.  On the shipped
tongue (1,802 nodes, 8,118 tets, r = 150) a force costs ~0.75 ms against 5.5 ms through
NumPy (whose einsum calls on (k, 3, 3) arrays are most of it): the two 5,406 × 150 BLAS
products ~0.45 ms, the tet kernel ~0.3 ms.  That is the floor of one exact force on one
core: the frame loop is bounded by the number of forces per frame.

The tangent Bᵀ K(Bz) B: the element tangents (12 × 12, the formula of :mod:`tonguevis.sim.stvk`)
summed by the kernel straight into a block-sparse (3 × 3 blocks) K of fixed pattern (~2 ms), then
K B (sparse, as CSR: ~9 ms) and Bᵀ (K B) (BLAS, ~4.5 ms): ~16 ms against ~75 ms through NumPy
and a fresh assembly.

Runs on the CPU (warp's CPU device: one thread; the products are the only work on the
other core).  Units SI: z in m, forces N, energy J, stiffness N/m.
"""

from __future__ import annotations

import threading

import numpy as np
import scipy.sparse as sp

_lock = threading.Lock()
_kernels = None


def _build():
    global _kernels
    with _lock:
        if _kernels is not None:
            return _kernels
        from tonguevis._backend import load_warp

        wp = load_warp()
        f64 = wp.float64

        @wp.func
        def deformation(u: wp.array(dtype=wp.vec3d), tets: wp.array(dtype=wp.int32, ndim=2),
                        grads: wp.array(dtype=wp.vec3d, ndim=2), e: int, offset: int):
            f = wp.identity(3, dtype=f64)
            for a in range(4):
                f = f + wp.outer(u[offset + tets[e, a]], grads[e, a])
            return f

        @wp.kernel
        def force_kernel(u: wp.array(dtype=wp.vec3d), tets: wp.array(dtype=wp.int32, ndim=2),
                         grads: wp.array(dtype=wp.vec3d, ndim=2), vol: wp.array(dtype=f64), mu: f64, lam: f64,
                         f: wp.array(dtype=wp.vec3d), energy: wp.array(dtype=f64)):
            e = wp.tid()
            fg = deformation(u, tets, grads, e, 0)
            eye = wp.identity(3, dtype=f64)
            strain = f64(0.5) * (wp.transpose(fg) * fg - eye)
            tr = wp.trace(strain)
            s = lam * tr * eye + f64(2.0) * mu * strain
            p = fg * s * (-vol[e])
            for a in range(4):
                wp.atomic_add(f, tets[e, a], p * grads[e, a])
            wp.atomic_add(energy, 0, vol[e] * (mu * wp.ddot(strain, strain) + f64(0.5) * lam * tr * tr))

        @wp.kernel
        def energy_kernel(u: wp.array(dtype=wp.vec3d), n_nodes: int, tets: wp.array(dtype=wp.int32, ndim=2),
                          grads: wp.array(dtype=wp.vec3d, ndim=2), vol: wp.array(dtype=f64), mu: f64, lam: f64,
                          energy: wp.array(dtype=f64)):
            frame, e = wp.tid()
            fg = deformation(u, tets, grads, e, frame * n_nodes)
            strain = f64(0.5) * (wp.transpose(fg) * fg - wp.identity(3, dtype=f64))
            tr = wp.trace(strain)
            wp.atomic_add(energy, frame, vol[e] * (mu * wp.ddot(strain, strain) + f64(0.5) * lam * tr * tr))

        @wp.kernel
        def tangent_kernel(u: wp.array(dtype=wp.vec3d), tets: wp.array(dtype=wp.int32, ndim=2),
                           grads: wp.array(dtype=wp.vec3d, ndim=2), vol: wp.array(dtype=f64), mu: f64, lam: f64,
                           slots: wp.array(dtype=wp.int32, ndim=3), blocks: wp.array(dtype=wp.mat33d)):
            e = wp.tid()
            fg = deformation(u, tets, grads, e, 0)
            eye = wp.identity(3, dtype=f64)
            strain = f64(0.5) * (wp.transpose(fg) * fg - eye)
            s = lam * wp.trace(strain) * eye + f64(2.0) * mu * strain
            ff = fg * wp.transpose(fg)
            v = vol[e]
            for a in range(4):
                ga = grads[e, a]
                fa = fg * ga
                sa = s * ga
                for b in range(4):
                    gb = grads[e, b]
                    fb = fg * gb
                    k = (wp.dot(gb, sa) * eye + lam * wp.outer(fa, fb) + mu * wp.dot(ga, gb) * ff
                         + mu * wp.outer(fb, fa))
                    wp.atomic_add(blocks, slots[e, a, b], v * k)

        _kernels = (wp, force_kernel, energy_kernel, tangent_kernel)
        return _kernels


class CompiledStVK:
    """The exact reduced StVK of a :class:`~tonguevis.sim.domains.DomainModel` ``dm`` by warp kernels.

    :meth:`force` (r,) N and :attr:`last_energy` J (of the same z), :meth:`energies` (F,) J,
    :meth:`tangent` (r, r) N/m; every tet of the mesh.
    """

    def __init__(self, dm):
        wp, self._force_k, self._energy_k, self._tangent_k = _build()
        self._wp = wp
        solid = dm.solid
        self.basis = np.ascontiguousarray(dm.basis)  # (3n, r)
        self.n_nodes = solid.n_nodes
        self.mu, self.lam = float(solid.mu), float(solid.lam)
        self._dev = "cpu"
        self._tets_np = np.ascontiguousarray(solid.tets, dtype=np.int32)
        self._tets = wp.array(self._tets_np, dtype=wp.int32, device=self._dev)
        self._grads = wp.array(np.ascontiguousarray(solid.grads), dtype=wp.vec3d, device=self._dev)
        self._vol = wp.array(np.ascontiguousarray(solid.volumes), dtype=wp.float64, device=self._dev)
        # scratch shared with warp (no copies per call)
        self._u = np.zeros((self.n_nodes, 3))
        self._f = np.zeros((self.n_nodes, 3))
        self._e = np.zeros(1)
        self._u_w = wp.array(self._u, dtype=wp.vec3d, device=self._dev, copy=False)
        self._f_w = wp.array(self._f, dtype=wp.vec3d, device=self._dev, copy=False)
        self._e_w = wp.array(self._e, dtype=wp.float64, device=self._dev, copy=False)
        self.last_energy = float("nan")
        self._pattern = None
        # the launch recorded once: its arguments are packed once (~60 µs a call otherwise)
        self._force_cmd = wp.launch(self._force_k, dim=len(self._tets_np),
                                    inputs=[self._u_w, self._tets, self._grads, self._vol, self.mu, self.lam],
                                    outputs=[self._f_w, self._e_w], device=self._dev, record_cmd=True)

    def force(self, z: np.ndarray) -> np.ndarray:
        """(r,) Bᵀ f_int(B z), N; sets :attr:`last_energy` to the elastic energy of B z (J)."""
        np.dot(self.basis, z, out=self._u.reshape(-1))
        self._f.fill(0.0)
        self._e.fill(0.0)
        self._force_cmd.launch()
        self.last_energy = float(self._e[0])
        return self._f.reshape(-1) @ self.basis

    def energies(self, z: np.ndarray, chunk: int = 256) -> np.ndarray:
        """(F,) elastic energy (J) of every frame of z (F, r)."""
        wp = self._wp
        z = np.atleast_2d(np.asarray(z, dtype=np.float64))
        out = np.zeros(len(z))
        for start in range(0, len(z), chunk):
            block = z[start:start + chunk]
            u = np.ascontiguousarray(block @ self.basis.T).reshape(-1, 3)
            e = np.zeros(len(block))
            wp.launch(self._energy_k, dim=(len(block), len(self._tets_np)),
                      inputs=[wp.array(u, dtype=wp.vec3d, device=self._dev, copy=False), self.n_nodes, self._tets,
                              self._grads, self._vol, self.mu, self.lam],
                      outputs=[wp.array(e, dtype=wp.float64, device=self._dev, copy=False)], device=self._dev)
            out[start:start + len(block)] = e
        return out

    def _build_pattern(self):
        """The block-sparse pattern of K (3 × 3 blocks, one per node pair sharing a tet) and each tet's slots."""
        tets = self._tets_np.astype(np.int64)
        n = self.n_nodes
        rows = np.repeat(tets, 4, axis=1).ravel()  # (k·16,) a-major
        cols = np.tile(tets, (1, 4)).ravel()
        key = rows * n + cols
        uniq, slot = np.unique(key, return_inverse=True)
        indices = (uniq % n).astype(np.int32)
        indptr = np.searchsorted(uniq // n, np.arange(n + 1)).astype(np.int32)
        self._bsr = sp.bsr_matrix((np.zeros((len(uniq), 3, 3)), indices, indptr), shape=(3 * n, 3 * n))
        self._blocks = self._bsr.data  # the kernel writes the matrix's own data (no copy per call)
        assert self._blocks.flags.c_contiguous and self._blocks.dtype == np.float64
        self._blocks_w = self._wp.array(self._blocks, dtype=self._wp.mat33d, device=self._dev, copy=False)
        self._slots = self._wp.array(slot.reshape(-1, 4, 4).astype(np.int32), dtype=self._wp.int32,
                                     device=self._dev)
        self._pattern = True

    def stiffness(self, z: np.ndarray) -> sp.bsr_matrix:
        """(3n, 3n) the full tangent stiffness K(B z), N/m (block-sparse; its data are reused by the next call)."""
        if self._pattern is None:
            self._build_pattern()
        np.dot(self.basis, z, out=self._u.reshape(-1))
        self._blocks.fill(0.0)
        self._wp.launch(self._tangent_k, dim=len(self._tets_np),
                        inputs=[self._u_w, self._tets, self._grads, self._vol, self.mu, self.lam, self._slots],
                        outputs=[self._blocks_w], device=self._dev)
        return self._bsr

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """(r, r) Bᵀ K(B z) B, N/m."""
        kb = self.stiffness(z).tocsr() @ self.basis  # scipy's CSR product is 3x its BSR one (9 against 29 ms)
        return self.basis.T @ kb
