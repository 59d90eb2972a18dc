"""The plane-strain biaxial boundary-value problem: kinematics, boundary conditions, assembly.

Small strain, tension positive, per unit out-of-plane thickness (forces in N/m, stiffness in Pa).
Discretization: skfem vector Lagrange elements (bilinear quads, 2x2 Gauss points by default, or
linear triangles with one point). The symmetric gradients of the basis functions are precomputed
once ("B-matrices", with skfem's ``Basis.dx`` weights), so that the Newton loop works on plain
arrays: strain = B u, f_int = sum B^T sigma dx, K = sum B^T D B dx (scipy.sparse).

Boundary conditions (docs/fem.md):
- bottom face y = ymin on rollers: u_y = 0 at every bottom node, u_x = 0 at the one bottom node
  nearest the middle (no rigid translation, no bias to one side);
- top face y = ymax: smooth rigid platen, u_y = -delta at every top node (driven), u_x free;
- lateral faces x = xmin, xmax: constant confining pressure sigma2 on the INITIAL faces
  (dead load, f_lat computed once). With small strain and Cauchy stresses read as
  reference-configuration stresses, this is the choice under which the perfect specimen
  reproduces the material point exactly (the material point holds its Cauchy s22 = sigma2).
The initial state is the isotropic state p0 = sigma2 of the material, uniform, so the initial
residual vanishes: the specimen starts in equilibrium with the confining pressure. The material
is any law of the material contract (``point.contract``): its parameter record says which
(``point.material_of``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
import scipy.sparse as sp
from scipy.sparse import _sparsetools
import skfem
from skfem import Basis, FacetBasis, ElementVector, LinearForm
from skfem.helpers import dot

from point.contract import material_of
from .adapter import MaterialField

__all__ = ["Imperfection", "Biaxial", "PatternGather"]


@dataclass(frozen=True)
class Imperfection:
    """A weaker zone: every quadrature point of the elements whose centroid lies in it gets the
    modified parameters: ``values``, a dict of the specimen's parameter fields -> their weak
    values (any law, e.g. {"mu_p": 0.5} for a Drucker-Prager specimen), and the H-model's
    shorthands phi_g [deg] and alpha0 [deg] (None keeps the specimen's value; ``values`` wins
    where both name a field).

    kind : "spot" (a disk of radius ``size`` * width centred at (x, y) given as fractions of the
    width and height; default on the left face at mid-height so the band can choose its own
    orientation) or "band" (a strip of half-width ``size`` * width through the centre of the
    specimen at ``angle`` [deg] from the horizontal).
    """

    kind: str = "spot"
    size: float = 0.1
    phi_g: float | None = 18.0
    alpha0: float | None = None
    x: float = 0.0
    y: float = 0.5
    angle: float = 45.0
    values: dict | None = None

    def __post_init__(self):
        if self.kind not in ("spot", "band"):
            raise ValueError(f"Imperfection.kind {self.kind!r} is not allowed: allowed 'spot' or 'band'")
        if not (np.isfinite(self.size) and 0 < self.size <= 1):
            raise ValueError(f"Imperfection.size = {self.size!r} is out of range: allowed 0 < size <= 1 "
                             "(fraction of the specimen width)")
        if not np.isfinite(self.angle):
            raise ValueError(f"Imperfection.angle = {self.angle!r} is out of range: allowed a finite "
                             "angle [deg]")
        if self.values is not None and not isinstance(self.values, dict):
            raise ValueError(f"Imperfection.values = {self.values!r}: allowed a dict of "
                             "parameter fields -> weak values")
        if self.phi_g is None and self.alpha0 is None and not self.values:
            raise ValueError("Imperfection needs a weak value (values, or the H-model's phi_g or "
                             "alpha0)")

    def changes(self) -> dict:
        """The weak values: field -> value (phi_g, alpha0 where given, then ``values``)."""
        ch = {k: v for k, v in (("phi_g", self.phi_g), ("alpha0", self.alpha0)) if v is not None}
        ch.update(self.values or {})
        return ch

    def params(self, base):
        """The weak zone's parameter record: ``base`` (of any law) with ``changes()``; a field
        the record does not have is refused (ValueError naming it and the record's fields)."""
        ch = self.changes()
        known = [f for f in base.__dataclass_fields__ if not f.startswith("_")]
        for k in ch:
            if k not in known:
                raise ValueError(f"{k} is no parameter of the {material_of(base).name} specimen's "
                                 f"{type(base).__name__}: allowed {', '.join(known)}")
        return base.replace(**ch)

    def elements(self, mesh: skfem.Mesh) -> np.ndarray:
        """Indices of the elements inside the weak zone."""
        c = mesh.p[:, mesh.t].mean(axis=1)             # (2, nelems) centroids
        x0, x1 = mesh.p[0].min(), mesh.p[0].max()
        y0, y1 = mesh.p[1].min(), mesh.p[1].max()
        w, h = x1 - x0, y1 - y0
        if self.kind == "spot":
            d = np.hypot(c[0] - (x0 + self.x * w), c[1] - (y0 + self.y * h))
        else:
            a = np.radians(self.angle)
            d = np.abs(-(c[0] - (x0 + 0.5 * w)) * np.sin(a) + (c[1] - (y0 + 0.5 * h)) * np.cos(a))
        inside = np.flatnonzero(d <= self.size * w)
        if inside.size == 0:   # at least the nearest element, so the option always does something
            inside = np.array([int(np.argmin(d))])
        return inside


class Biaxial:
    """Plane-strain biaxial specimen: mesh, bases, dofs, boundary conditions, assembly.

    mesh : skfem MeshQuad or MeshTri (see fem.mesh). params : the parameter record of the
    specimen's law (HParams, DPParams, ...: ``point.material_of``); the confining pressure
    sigma2 is params.p0 [Pa] (initial state in equilibrium with it).
    imperfection : optional Imperfection. intorder : quadrature order (default 2: 2x2 Gauss
    points on quads, 1 point on linear triangles).
    """

    def __init__(self, mesh: skfem.Mesh, params, imperfection: Imperfection | None = None,
                 intorder: int | None = None, allow_sliding: bool = True):
        self.mesh = mesh
        self.params = params
        self.law = material_of(params)
        self.sigma2 = float(params.p0)
        if isinstance(mesh, skfem.MeshQuad1):
            elem, order = skfem.ElementQuad1(), 2
        elif isinstance(mesh, skfem.MeshTri1):
            elem, order = skfem.ElementTriP1(), 1
        else:
            raise ValueError(f"mesh must be a linear MeshQuad or MeshTri, got {type(mesh).__name__}")
        self.element = ElementVector(elem)
        self.basis = Basis(mesh, self.element, intorder=order if intorder is None else intorder)
        b = self.basis
        self.nel = mesh.t.shape[1]
        self.dx = np.asarray(b.dx)                                     # (nel, nqp) [m^2]
        self.nqp = self.dx.shape[1]
        self.npts = self.nel * self.nqp
        self.ndofs = b.N
        self.edofs = np.asarray(b.element_dofs)                         # (nbf, nel)
        self.nbf = self.edofs.shape[0]
        # symmetric gradients of the basis functions: (nbf, 2, 2, nel, nqp) [1/m]
        g = np.stack([np.asarray(b.basis[j][0].grad) for j in range(self.nbf)])
        self.Bsym = 0.5 * (g + np.swapaxes(g, 1, 2))
        # the same as (P, nbf, 4) rows (P = nel*nqp points, C order (e, q)) for batched matmuls
        self._Bp = np.ascontiguousarray(
            self.Bsym.reshape(self.nbf, 4, self.npts).transpose(2, 0, 1))
        self._wp = self.dx.reshape(self.npts)
        self._elem_w = self.dx / self.dx.sum(axis=1, keepdims=True)     # per_element's weights
        self._strains = []                                               # strain()'s memory
        rows = np.broadcast_to(self.edofs[:, None, :], (self.nbf, self.nbf, self.nel))
        cols = np.broadcast_to(self.edofs[None, :, :], (self.nbf, self.nbf, self.nel))
        self._rows = rows.transpose(2, 0, 1).ravel()   # element-major like the element matrices
        self._cols = cols.transpose(2, 0, 1).ravel()
        self._setup_csr()
        self._setup_bcs()
        # material groups
        groups = [(params, np.arange(self.npts))]
        self.imperfection = imperfection
        self.weak_elements = np.array([], dtype=int)
        if imperfection is not None:
            weak = imperfection.elements(mesh)
            mask = np.zeros(self.nel, dtype=bool)
            mask[weak] = True
            pts = np.repeat(mask, self.nqp)
            groups = [(params, np.flatnonzero(~pts)), (imperfection.params(params), np.flatnonzero(pts))]
            self.weak_elements = weak
        self.material = MaterialField(self.npts, groups, allow_sliding=allow_sliding)

    def _setup_csr(self):
        """The CSR pattern of K and, for every stored entry, the element-matrix entries it sums,
        in the order ``coo_matrix(...).tocsr()`` sums them (scipy's coo_tocsr keeps the input
        order within a row, csr_sort_indices then sorts each row by column with a sort whose
        moves depend on the columns only, and csr_sum_duplicates adds each run of equal columns
        left to right): found once by converting the entry numbers themselves, so that
        ``stiffness`` gives the same bits as the conversion without redoing it at every call."""
        n = self._rows.size
        M = self.ndofs
        if n == 0 or max(M, n) >= np.iinfo(np.int32).max:
            self._csr = None
            return
        idx = np.int32
        indptr = np.empty(M + 1, dtype=idx)
        indices = np.empty(n, dtype=idx)
        tags = np.empty(n)
        _sparsetools.coo_tocsr(M, M, n, self._rows.astype(idx), self._cols.astype(idx),
                               np.arange(n, dtype=float), indptr, indices, tags)
        _sparsetools.csr_sort_indices(M, indptr, indices, tags)
        rows = np.repeat(np.arange(M, dtype=np.int64), np.diff(indptr))
        key = rows * M + indices
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        counts = np.bincount(rows[starts], minlength=M)
        self._csr = (tags.astype(np.int64), starts, indices[starts],
                     np.r_[0, np.cumsum(counts)].astype(idx))

    # -- boundary conditions -----------------------------------------------------------------
    def _setup_bcs(self):
        p = self.mesh.p
        x0, x1 = p[0].min(), p[0].max()
        y0, y1 = p[1].min(), p[1].max()
        self.width, self.height = float(x1 - x0), float(y1 - y0)
        tol = 1e-9 * max(self.width, self.height)
        nd = np.asarray(self.basis.nodal_dofs)                          # (2, nnodes): x, y dofs
        bottom = np.flatnonzero(np.abs(p[1] - y0) < tol)
        top = np.flatnonzero(np.abs(p[1] - y1) < tol)
        mid = bottom[np.argmin(np.abs(p[0, bottom] - 0.5 * (x0 + x1)))]
        self.top_y = nd[1, top]
        self.bottom_y = nd[1, bottom]
        self.fixed_x = np.array([nd[0, mid]])
        self.prescribed = np.unique(np.concatenate([self.top_y, self.bottom_y, self.fixed_x]))
        self.free = np.setdiff1d(np.arange(self.ndofs), self.prescribed)
        # lateral confining pressure on the initial faces: traction t = sigma . n = -sigma2 n
        lat = self.mesh.facets_satisfying(lambda x: (np.abs(x[0] - x0) < tol) | (np.abs(x[0] - x1) < tol))
        fb = FacetBasis(self.mesh, self.element, facets=lat)
        s2 = self.sigma2

        @LinearForm
        def pressure(v, w):
            return -s2 * dot(w.n, v)

        self.f_lat = np.asarray(pressure.assemble(fb))                  # (ndofs,) [N/m]
        # reduced dofs of the force-controlled platen: free dofs + one platen dof tying top u_y
        n_free = self.free.size
        T = sp.lil_matrix((self.ndofs, n_free + 1))
        T[self.free, np.arange(n_free)] = 1.0
        T[self.top_y, n_free] = 1.0
        self.T_platen = T.tocsr()

    def prescribed_values(self, delta: float) -> np.ndarray:
        """Values of the prescribed dofs (order of self.prescribed) for a platen displacement
        ``delta`` [m] downwards (compression positive)."""
        u = np.zeros(self.ndofs)
        u[self.top_y] = -delta
        return u[self.prescribed]

    # -- kinematics and assembly --------------------------------------------------------------
    def strain(self, u: np.ndarray) -> np.ndarray:
        """(2, 2, npts) small strain of the nodal displacement u (ndofs,) [m], tension +.

        The last two results are remembered with a copy of their u: the converged iterate's
        strain is asked again by the step's record and, as the committed strain, by the next
        step's Newton (a comparison of u instead of the contraction; a new array each call)."""
        u = np.asarray(u)
        for key, eps in self._strains:
            if key.shape == u.shape and key.dtype == u.dtype and np.array_equal(key, u):
                return eps.copy()
        ue = u[self.edofs]                                              # (nbf, nel)
        eps = np.einsum("je,jabeq->abeq", ue, self.Bsym, optimize=True).reshape(2, 2, self.npts)
        self._strains = [(u.copy(), eps.copy())] + self._strains[:1]
        return eps

    def internal_force(self, sigma: np.ndarray) -> np.ndarray:
        """f_int = sum_points B^T sigma dx, shape (ndofs,) [N/m]; sigma (2, 2, npts) [Pa]."""
        s = sigma.reshape(4, self.npts).T * self._wp[:, None]           # (P, 4)
        fe = np.einsum("pja,pa->pj", self._Bp, s)                       # (P, nbf)
        fe = fe.reshape(self.nel, self.nqp, self.nbf).sum(axis=1)       # (nel, nbf)
        return np.bincount(self.edofs.T.ravel(), weights=fe.ravel(), minlength=self.ndofs)

    def stiffness(self, D: np.ndarray) -> sp.csr_matrix:
        """K = sum_points B^T D B dx, (ndofs, ndofs) csr [Pa]; D (2, 2, 2, 2, npts) [Pa]."""
        Dp = np.ascontiguousarray(D.reshape(4, 4, self.npts).transpose(2, 0, 1))   # (P, 4, 4)
        Ke = _element_matrices(self._Bp, Dp, self._wp, self.nqp)                  # (nel, nbf^2)
        if self._csr is None:
            K = sp.coo_matrix((Ke.ravel(), (self._rows, self._cols)), shape=(self.ndofs, self.ndofs))
            return K.tocsr()
        perm, starts, indices, indptr = self._csr
        data = _sum_runs(Ke.ravel(), perm, starts, np.empty(starts.size))
        K = sp.csr_matrix((data, indices.copy(), indptr.copy()), shape=(self.ndofs, self.ndofs))
        K.has_canonical_format = True          # sorted, no duplicates: what tocsr() leaves
        return K

    def platen_force(self, f_int: np.ndarray) -> float:
        """Vertical force of the specimen on the top platen, tension + [N/m]."""
        return float(np.sum(f_int[self.top_y]))

    def volume_average(self, field: np.ndarray) -> np.ndarray:
        """Volume average over the specimen of a (..., npts) field."""
        return np.sum(field * self._wp, axis=-1) / np.sum(self._wp)

    def per_element(self, field: np.ndarray, how: str = "mean") -> np.ndarray:
        """(..., npts) point field -> (..., nel): volume mean or minimum over each element's points."""
        f = field.reshape(field.shape[:-1] + (self.nel, self.nqp))
        if how == "min":
            return f.min(axis=-1)
        return np.sum(f * self._elem_w, axis=-1)


class PatternGather:
    """``f(K)`` for a stream of csr matrices K of one sparsity pattern, f a restructuring of the
    stored entries (row / column selection, permutation, transposition, format conversion: no
    sum, no entry dropped), e.g. ``lambda K: K[free][:, free].tocsc()``. For each new pattern f
    runs once on the entry numbers (1, 2, ... nnz as floats, exact), which gives the position in
    K.data of every entry of the result; then each call is a gather into a matrix with f's index
    arrays: the same arrays, the same bits as f(K) itself, without the indexing and conversions.
    ``sparse`` is the result's class (sp.csc_matrix or sp.csr_matrix)."""

    def __init__(self, f):
        self.f = f
        self._pattern = None

    def __call__(self, K):
        pat = self._pattern
        if pat is None or not (np.array_equal(pat[0], K.indptr) and np.array_equal(pat[1], K.indices)):
            self._setup(K)
        cls, src, indices, indptr, shape = self._map
        return cls((K.data[src], indices.copy(), indptr.copy()), shape=shape)

    def _setup(self, K):
        nnz = K.nnz
        if nnz >= 2 ** 52:
            raise ValueError("too many entries to number exactly")

        def tagged(numbers):
            return self.f(sp.csr_matrix((numbers, K.indices.copy(), K.indptr.copy()), shape=K.shape))
        R = tagged(np.arange(1, nnz + 1, dtype=float))
        src = R.data.astype(np.int64) - 1
        # a second numbering (in reverse) must land on the same entries: not so if f sums or
        # scales entries, or drops or adds some
        R2 = tagged(np.arange(nnz, 0, -1, dtype=float))
        if not (np.all(R.data == src + 1) and np.all((src >= 0) & (src < nnz))
                and np.array_equal(R2.data, (nnz - src).astype(float))
                and np.array_equal(R2.indices, R.indices) and np.array_equal(R2.indptr, R.indptr)):
            raise ValueError("f is not a restructuring of the stored entries")
        self._map = (type(R), src, R.indices.copy(), R.indptr.copy(), R.shape)
        self._pattern = (K.indptr.copy(), K.indices.copy())


@numba.njit(cache=True, fastmath={"contract"})
def _element_matrices(Bp, Dp, wp, nqp):
    """Element stiffness matrices (nel, nbf * nbf), row-major: Ke = sum over the element's points
    q (in order, from the first) of (B D)_q w_q B_q^T, with B = Bp[p] (nbf, 4), D = Dp[p] (4, 4),
    w = wp[p], p = e nqp + q. The operations of what the assembly did before with numpy,
    ``(matmul(Bp, Dp) * wp) @ Bp^T`` then ``.sum(axis=1)`` over the points, in their order: each
    product entry accumulated over k from zero with fused multiply-adds (``contract``: acc + a b
    becomes one fma), 0 + acc (a store into a zeroed C), then the weight. That is how numpy's
    matmul rounds on this machine (OpenBLAS's x86-64 dgemm kernels accumulate so): the same bits
    as numpy on the benchmark's tangents, and every output of the 20 x 40 benchmark and of the
    default run bit-identical to the numpy route's. Elsewhere the kernel's K does not depend on
    the BLAS (tests/fem/test_fast_paths.py bounds its difference from numpy's by the products'
    rounding). 2 x faster: no BLAS call per 8 x 4 product, no (P, nbf, nbf) intermediate."""
    P, nb, nc = Bp.shape
    nel = P // nqp
    m = nb * nb
    E = np.empty(nel * m)             # flat (a 2-D output measured 30 % slower)
    BD = np.empty((nb, nc))
    for e in range(nel):
        for q in range(nqp):
            p = e * nqp + q
            for i in range(nb):
                for j in range(nc):
                    acc = 0.0
                    for k in range(nc):
                        acc = acc + Bp[p, i, k] * Dp[p, k, j]
                    BD[i, j] = (0.0 + acc) * wp[p]
            for i in range(nb):
                for j in range(nb):
                    acc = 0.0
                    for k in range(nc):
                        acc = acc + BD[i, k] * Bp[p, j, k]
                    if q == 0:
                        E[e * m + i * nb + j] = 0.0 + acc
                    else:
                        E[e * m + i * nb + j] += 0.0 + acc
    return E.reshape(nel, m)


@numba.njit(cache=True)
def _sum_runs(Ke, perm, starts, out):
    """out[g] = Ke[perm[starts[g]]] + Ke[perm[starts[g] + 1]] + ... (left to right) up to the
    next start, Ke = the element matrices flattened: the entries of K as csr_sum_duplicates adds
    them."""
    m = starts.size
    n = perm.size
    for g in range(m):
        a = starts[g]
        b = starts[g + 1] if g + 1 < m else n
        s = Ke[perm[a]]
        for k in range(a + 1, b):
            s += Ke[perm[k]]
        out[g] = s
    return out
